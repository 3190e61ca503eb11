"""What a stage is: ONE declaration (``Stage``) holding everything the planner, the cache key,
``--explain`` and the tests read about it — its name, the artifact it produces, the artifacts it
consumes, the scene fields it reads (and the canonical form of them in its cache key), when the
scene cannot produce it or already gives it, and the function that computes it. The code it
depends on is not declared: torquebench.stages.codedeps derives it from the import graph of the
modules that define these functions."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass


def no_params(scene, seed) -> dict:
    return {}


def always(scene) -> None:
    return None


def reads_all(scene, art: str) -> bool:
    return True


@dataclass(frozen=True)
class Stage:
    """One stage of the graph.

    run(scene, inp, seed) -> value     the computation; ``inp`` maps each consumed artifact
                                       (``needs`` without the ``?``) to its value or None
    needs                              artifacts consumed; ``"x?"``: optional (used when the scene
                                       can produce or gives x)
    reads                              the scene fields it reads (for people and --explain)
    params(scene, seed) -> dict        those fields in canonical form: part of the cache key
    feasible(scene) -> str | None      why this scene cannot produce ``gives`` (None: it can)
    given(scene) -> str | None         why this scene gives ``gives`` itself (the stage is skipped)
    load(scene) -> value               reads the given artifact (None: nothing to load)
    uses(scene, art) -> bool           whether this scene's run reads its input ``art``
    inputs(scene, have) -> [art]       inputs chosen from what the rest of the plan computes
                                       (``have``), planned after the others (the report)
    note(scene, have) -> str           what --explain adds to the reason of a run
    cached                             False: always runs, never cached (it writes files)
    aliases                            other output names that ask for ``gives`` (a scene's [outputs]
                                       want and ``--only`` take them)
    scene_output                       a scene's [outputs] want may name ``gives`` itself
    robot                              the scenes it is planned for: "planar" (a robot TOML chain)
                                       or "spatial" (a URDF robot, estimator.spatial)
    """
    name: str
    gives: str
    doc: str
    run: Callable
    needs: tuple = ()
    reads: tuple = ()
    params: Callable = no_params
    feasible: Callable = always
    given: Callable = always
    load: Callable | None = None
    uses: Callable = reads_all
    inputs: Callable | None = None
    note: Callable | None = None
    cached: bool = True
    aliases: tuple = ()
    scene_output: bool = False
    robot: str = "planar"

    @property
    def inputs_declared(self) -> tuple[str, ...]:
        """``needs`` without the optional marks."""
        return tuple(n.rstrip("?") for n in self.needs)

    def functions(self) -> list[Callable]:
        """Every function of the declaration (their modules seed the derived code dependencies)."""
        return [f for f in (self.run, self.params, self.feasible, self.given, self.load, self.uses,
                            self.inputs, self.note) if f is not None]
