"""The graph runner: which stages a scene's outputs need, in what order, and running them.

The plan is built backwards from the requested outputs over the stage declarations
(torquebench.stages.registry) and reads only them: what a stage consumes (``needs``, ``uses``),
whether the scene can produce or already gives an artifact (``feasible``, ``given``), its canonical
inputs (``params``) and its code (derived: torquebench.stages.codedeps) for its cache key
(torquebench.stages.cachekey). A stage whose result the scene gives (a ``strain_per_Nm``, a
calibration file, a recorded log) is not run; a given artifact with a reader (``load``) is read.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

from torquebench.stages import registry
from torquebench.stages.cachekey import stage_key
from torquebench.stages.declaration import Stage
from userio.errors import InputError

DEFAULT_OUTPUTS = ("localization_error", "predicted_error")
SPATIAL_OUTPUTS = ("spatial_localization_error", "spatial_predicted_error")


def scene_robot(scene) -> str:
    """"spatial" for a 3-D scene (a URDF robot), else "planar": the stages planned for it."""
    return getattr(scene, "robot_kind", "planar")


def scene_stages(scene) -> tuple:
    """The stages a scene of this kind may run (``Stage.robot``), in execution order."""
    kind = scene_robot(scene)
    return tuple(s for s in registry.stages() if s.robot == kind)


@dataclass
class Step:
    stage: Stage
    action: str           # "run" | "skip" | "cached"
    reason: str
    key: str = ""
    read: bool = False    # a given artifact that the run reads (Stage.load)


def feasible(scene, art: str) -> str | None:
    """Why ``art`` cannot be produced by this scene, or None."""
    st = registry.by_gives().get(art)
    return f"no stage produces {art!r}" if st is None else st.feasible(scene)


def given(scene, art: str) -> str | None:
    """Why artifact ``art`` need not be computed (the scene gives it), or None."""
    st = registry.by_gives().get(art)
    return None if st is None else st.given(scene)


def default_outputs(scene) -> tuple:
    """What a scene without [outputs] want computes, by its kind."""
    if scene_robot(scene) == "spatial":
        return SPATIAL_OUTPUTS
    return DEFAULT_OUTPUTS if scene.sim is not None else ("estimates",) if scene.chain.log_file \
        else ("error_map",) if scene.prediction is not None \
        else ("sensitivity",)          # a static scene: the sensor model only (run by `reproduce`)


def scene_seed(scene) -> int:
    if scene_robot(scene) == "spatial":
        return int(scene.spec.seed)
    s = scene.sim.sensors.seed if scene.sim is not None else 0
    return int(s)


def plan(scene, outputs=None, cache=None, seed=None, force=False) -> list[Step]:
    """Steps in execution order, built backwards from ``outputs``."""
    stages = scene_stages(scene)
    producer = {s.gives: s for s in stages}
    alias = {a: s.gives for s in stages for a in s.aliases}
    chain = getattr(scene, "chain", None)
    wants = [alias.get(o, o) for o in (outputs or (chain.outputs if chain is not None else None)
                                       or default_outputs(scene))]
    for w in wants:
        if w not in producer:
            raise InputError(f"{scene.path}: outputs: unknown output {w!r}")
        why = producer[w].feasible(scene)
        if why:
            raise InputError(f"{scene.path}: outputs: nothing in the scene can produce {w!r} ({why})")
    needed: dict[str, str] = {}

    def visit(art, reason):
        if art in needed:
            return
        st = producer[art]
        if st.given(scene) and st.load is not None:
            needed[art] = "given"
            return
        if st.feasible(scene):               # no source for it: nothing to plan
            return
        needed[art] = reason
        for n in st.needs:
            opt, n = n.endswith("?"), n.rstrip("?")
            if n not in producer or not st.uses(scene, n):
                continue
            if opt and (producer[n].given(scene) or producer[n].feasible(scene)):
                continue
            visit(n, f"needed by {st.name}")

    later = [w for w in wants if producer[w].inputs is not None]
    for w in wants:
        if w not in later:
            visit(w, "requested output")
    for w in later:                        # inputs chosen from what the rest of the plan computes
        st = producer[w]
        arts = st.inputs(scene, set(needed))
        needed[w] = "requested output"
        for art in sorted(arts):
            visit(art, f"needed by {st.name}")
    seed = scene_seed(scene) if seed is None else seed
    steps, keys = [], {}
    for st in stages:
        if st.given(scene) and st.load is not None:      # read, not computed: keyed by what it reads
            keys[st.gives] = stage_key(st, st.params(scene, seed), [])
        if st.gives not in needed or needed[st.gives] == "given":
            g = st.given(scene)
            steps.append(Step(st, "skip", g or "not needed for the requested outputs", keys.get(st.gives, "")))
            continue
        if not st.cached:                  # writes files: always runs, never cached
            note = st.note(scene, set(needed) - {st.gives}) if st.note else ""
            steps.append(Step(st, "run", needed[st.gives] + note))
            continue
        up = [keys.get(n, "") if st.uses(scene, n) else "" for n in st.inputs_declared]
        key = stage_key(st, st.params(scene, seed), up)
        keys[st.gives] = key
        if cache is not None and not force and cache.has(key):
            steps.append(Step(st, "cached", f"{needed[st.gives]}; result in the cache", key))
        else:
            steps.append(Step(st, "run", needed[st.gives], key))
    used = {n for s in steps if s.action != "skip" for n in s.stage.inputs_declared
            if s.stage.uses(scene, n)}
    for s in steps:
        s.read = s.action == "skip" and s.stage.load is not None and bool(s.stage.given(scene)) \
            and (s.stage.gives in used or needed.get(s.stage.gives) == "given")
    return steps


def execute(scene, outputs=None, cache=None, seed=None, force=False, counter=None) -> tuple[dict, list]:
    """Run the plan; returns (artifacts, [(stage, action, seconds)])."""
    seed = scene_seed(scene) if seed is None else seed
    steps = plan(scene, outputs, cache, seed, force)
    arts = {s.stage.gives: s.stage.load(scene) for s in steps if s.read}
    timing = []
    for s in steps:
        if s.action == "skip":
            continue
        t0 = time.perf_counter()
        if s.action == "cached":
            value = cache.get(s.key)
            if value is None:                    # corrupt entry: reported by the cache, recompute
                s.action = "run"
        if s.action == "run":
            inp = {n: arts.get(n) for n in s.stage.inputs_declared}
            value = s.stage.run(scene, inp, seed)
            if counter is not None:
                counter[s.stage.name] = counter.get(s.stage.name, 0) + 1
            if cache is not None and s.key and s.stage.cached:
                cache.put(s.key, value)
        arts[s.stage.gives] = value
        timing.append((s.stage.name, s.action, time.perf_counter() - t0))
    return arts, timing
