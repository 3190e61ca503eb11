"""The commands' side of the one output policy (``userio.outputs``, where the rules live).

Every command builds an ``Outputs`` plan from its arguments (what it reads, what it writes, its
replace option), checks it before any work, and runs inside ``with plan.active():``:

    plan = Outputs(force=args.force)
    plan.input("LOG.csv", args.log, log=True)      # the log and its side files
    plan.file("--out", args.out)
    with plan.active():                            # checked here; every writer obeys it
        ...

``prepare_file`` / ``prepare_dir`` are the one-output shortcuts kept for older callers.
"""

from __future__ import annotations

from pathlib import Path

from userio.outputs import Outputs, make_dir, safe_stem, same_file  # noqa: F401  (re-exported)


def prepare_dir(directory: str | Path, option: str) -> Path:
    """Create ``directory`` if missing; a file in its way is an InputError."""
    directory = Path(directory)
    make_dir(directory, option)
    return directory


def prepare_file(path: str | Path | None, option: str, *, force: bool = False,
                 inputs: tuple = (), force_flag: str | None = "--force") -> Path | None:
    """Check one output file before the work (the rules of userio.outputs) and create its
    directory. Returns the path (None passes through)."""
    if path is None:
        return None
    plan = Outputs(force=force, force_flag=force_flag)
    for i, given in enumerate(inputs):
        plan.input(f"input {i + 1}", given)
    plan.file(option, path)
    plan.check()
    return Path(path)


def scene_plan(scene, *, force: bool = False, force_flag: str | None = "--force") -> Outputs:
    """A plan whose inputs are every file a run of ``scene`` reads (torquebench.scenes.scene_inputs)."""
    from torquebench.scenes import scene_inputs

    plan = Outputs(force=force, force_flag=force_flag)
    for label, p in scene_inputs(scene):
        plan.input(label, p)
    return plan


def foreign_files(out_dir: Path, stems, force: bool = False) -> list[Path]:
    """Files in ``out_dir`` that a report builder of these areas may write (a name containing one
    of ``stems``; .md/.png/.csv/.json) and that the tool did not write there (its manifest)."""
    from userio.outputs import is_own

    out_dir = Path(out_dir)
    if force or not out_dir.is_dir():
        return []
    return sorted(p for p in out_dir.iterdir() if p.suffix in (".md", ".png", ".csv", ".json")
                  and any(st.lower() in p.name.lower() for st in stems) and not is_own(p))


def run_plan(scene, outputs=None, *, force: bool = False, force_flag: str | None = "--overwrite") -> Outputs:
    """The plan of a scene run through the stage graph: the scene's inputs, and — when the run
    writes reports — the report directory ([outputs] dir, or out/<safe scene name>), the scene's
    summary ``<safe name>.md`` in it, and a refusal up front of files there of the report names
    that the tool did not write (without ``force``)."""
    from torquebench import pipeline as P
    from userio.errors import InputError

    plan = scene_plan(scene, force=force, force_flag=force_flag)
    steps = P.plan(scene, outputs, None)
    report = next((s for s in steps if s.stage.name == "report" and s.action == "run"), None)
    if report is None:
        return plan
    d = P.report_dir(scene)
    shipped = bool(scene.chain.regenerate_shipped)
    plan.directory("[outputs] dir", d, shipped=shipped)
    plan.file_in("[outputs] dir", d, P.summary_name(scene))
    areas, _ = P.report_areas(scene, {s.stage.gives for s in steps if s.action != "skip"})
    clash = [] if shipped else foreign_files(d, [*areas, "README"], force)
    if clash:
        raise InputError(f"[outputs] dir: {clash[0]} exists and was not written by torquebench; "
                         + (f"add {force_flag} to replace it or " if force_flag else "")
                         + "choose another [outputs] dir")
    return plan
