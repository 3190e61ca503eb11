"""What a scene run reads and writes, declared on the one output plan (``userio.outputs`` holds
every rule: outputs never inputs, no replacing without the force option, directories created,
atomic writes through ``userio.files``).

Every command builds an ``Outputs`` plan from its arguments, checks it before any work, and runs
inside ``with plan.active():``::

    plan = Outputs(force=args.force)
    plan.input("LOG.csv", args.log, log=True)      # the log and its side files
    plan.file("--out", args.out)
    with plan.active():                            # checked here; every writer obeys it
        ...

A scene's inputs and report directory come from the scene (``scene_plan``, ``run_plan``).
"""

from __future__ import annotations

from userio.outputs import Outputs


def scene_plan(scene, *, force: bool = False, force_flag: str | None = "--force") -> Outputs:
    """A plan whose inputs are every file a run of ``scene`` reads (torquebench.scenes.scene_inputs)."""
    from torquebench.scenes import scene_inputs

    plan = Outputs(force=force, force_flag=force_flag)
    for label, p in scene_inputs(scene):
        plan.input(label, p)
    return plan


def run_plan(scene, outputs=None, *, force: bool = False, force_flag: str | None = "--overwrite") -> Outputs:
    """The plan of a scene run through the stage graph: the scene's inputs, and — when the run
    writes reports — the report directory ([outputs] dir, or out/<safe scene name>) with the names
    of its reports (refused up front when such a file is not the tool's, userio.outputs rule 8), and
    the scene's summary ``<safe name>.md`` in it."""
    from torquebench import pipeline as P

    plan = scene_plan(scene, force=force, force_flag=force_flag)
    steps = P.plan(scene, outputs, None)
    report = next((s for s in steps if s.stage.name == "report" and s.action == "run"), None)
    if report is None:
        return plan
    d = P.report_dir(scene)
    areas, _ = P.report_areas(scene, {s.stage.gives for s in steps if s.action != "skip"})
    plan.directory("[outputs] dir", d, shipped=bool(scene.chain.regenerate_shipped),
                   names=[*areas, "README"])
    plan.file_in("[outputs] dir", d, P.summary_name(scene))
    return plan
