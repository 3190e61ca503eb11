"""`torquebench simulate SCENE.toml --out LOG.csv`: run a scene, write the log and its truth.

A view over the stage graph (torquebench.pipeline): the scene (with the command line's overrides)
asks for the ``log`` (simulation → sensor_log) or, for a static scene, the ``static_log``
(static_holds); results come from the stage cache when the same scene was run before."""

from __future__ import annotations

import sys
from pathlib import Path

from userio.errors import InputError

HELP = "simulate a scene file: write a sensor log CSV (docs/conventions.md), LOG.truth.csv and its sensor timing LOG.timing.toml beside it"
EXAMPLES = """\
torquebench simulate scenes/paper_floating_link1.toml --out out/floating_link1.csv
torquebench simulate scenes/paper_fixed_link2.toml --out out/fixed_link2.csv --seed 7 --duration 1.0 --json
torquebench simulate scenes/spatial/quadruped_leg_pokes.toml --out out/leg_pokes.csv --duration 0.3
"""


def add_arguments(parser) -> None:
    parser.add_argument("scene", type=Path, help="scene TOML file (docs/conventions.md), e.g. scenes/paper_floating_link1.toml")
    parser.add_argument("--out", type=Path, required=True, help="sensor log CSV to write (SI units); LOG.truth.csv and LOG.timing.toml are written beside it; directory created, existing files kept unless --force")
    parser.add_argument("--integrator", default=None,
                        help="integrator: RK45, DOP853, Radau, BDF, LSODA or RK4 (default: the scene's [integrator] method)")
    parser.add_argument("--seed", type=int, default=None, help="sensor-noise seed (default: the scene's [sensors] seed)")
    parser.add_argument("--duration", type=float, default=None, help="simulated time in s, dynamic scenes (default: the scene's duration_s)")
    parser.add_argument("--force", action="store_true", help="replace existing log and truth files")
    parser.add_argument("--max-run-time", type=float, default=600.0, metavar="S",
                        help="refuse a run predicted (or found) to take longer than S seconds (default: %(default)s)")
    parser.add_argument("--error-tolerance", type=float, default=None, metavar="RAD",
                        help="warn when the integration error estimate q_rad_error_estimate exceeds RAD (default: no check)")


def truth_path(out: Path) -> Path:
    """LOG.csv → LOG.truth.csv."""
    return out.with_name(out.stem + ".truth" + (out.suffix or ".csv"))


def scene_from_args(args, max_run_time_s: float):
    """The scene file with the command line's overrides (seed, integrator, duration, run limit)."""
    from dataclasses import replace

    from torquebench.scenes import load_scene, with_overrides, with_seed

    scene = with_seed(load_scene(args.scene), args.seed)
    if scene.sim is None and scene.static is None:
        raise InputError(f"{args.scene}: source.log: the scene reads a recorded log; there is "
                         "nothing to simulate")
    if scene.sim is not None:
        if args.integrator is not None:
            from estimator.sim.config import INTEGRATORS
            if args.integrator not in INTEGRATORS:
                raise InputError(f"--integrator: must be one of {', '.join(INTEGRATORS)}, "
                                 f"got {args.integrator!r}")
            scene = with_overrides(scene, integrator=args.integrator)
        if args.duration is not None:
            if not (args.duration > 0 and args.duration < float("inf")):
                raise InputError(f"--duration: must be > 0, got {args.duration}")
            scene = with_overrides(scene, duration_s=args.duration)
    return replace(scene, max_run_time_s=max_run_time_s)


def run(args) -> int:
    from estimator.noise import noise_side_file
    from estimator.sim.output import timing_path
    from torquebench.outputs import scene_plan
    from userio.errors import finite, seed

    seed(args.seed)
    if args.duration is not None:
        finite(args.duration, "--duration", positive=True)
    out, tpath = Path(args.out), truth_path(Path(args.out))
    timing_file, noise_file = timing_path(out), noise_side_file(out)
    if out.suffix == ".toml":
        raise InputError(f"--out: {out} looks like a scene/robot file; refusing to overwrite it "
                         "with a log (the log is a CSV)")
    from estimator.spatial.scene import is_spatial_scene
    if is_spatial_scene(args.scene):                  # a URDF robot: the 3-D simulator
        from estimator.spatial.scene import load_spatial_scene
        from torquebench.spatial_cli import simulate as simulate_3d
        from userio.outputs import Outputs

        robot = load_spatial_scene(args.scene).robot
        plan = Outputs(force=args.force)              # the same output rules as the planar path
        plan.input("scene", args.scene)
        decl = Path(robot.source) if str(robot.source).endswith(".toml") else None
        for label, p in (("the scene's robot", decl), ("the scene's URDF", robot.urdf_path)):
            plan.input(label, p)
        for label, p in (("--out", out), ("truth (--out with .truth.csv)", tpath),
                         ("timing (--out with .timing.toml)", timing_file),
                         ("noise (--out with .noise.toml)", noise_file)):
            plan.file(label, p)
        with plan.check().active():
            return simulate_3d(args)
    tol = getattr(args, "error_tolerance", None)
    if tol is not None:
        finite(tol, "--error-tolerance", positive=True)
    max_run = finite(getattr(args, "max_run_time", 600.0), "--max-run-time", positive=True)
    scene = scene_from_args(args, max_run)
    plan = scene_plan(scene, force=args.force)        # the scene and every file it reads
    for label, p in (("--out", out), ("truth (--out with .truth.csv)", tpath),
                     ("timing (--out with .timing.toml)", timing_file),
                     ("noise (--out with .noise.toml)", noise_file)):
        plan.file(label, p)
    with plan.active():                               # checked now; every write obeys it
        return _simulate(args, scene, out, tpath, timing_file, noise_file, tol)


def _simulate(args, scene, out, tpath, timing_file, noise_file, tol) -> int:
    from estimator.sim.output import log_files
    from torquebench import pipeline as P
    from torquebench.cache import Cache
    from torquebench.io import print_json
    from userio.files import remove, write_files_atomic

    want = "log" if scene.sim is not None else "static_log"    # the stage graph: simulation → sensor_log
    arts, _ = P.execute(scene, [want], Cache())
    log, truth, stats = (arts[want][k] for k in ("log", "truth", "stats"))
    noise = arts[want].get("noise")
    # log + truth + timing (+ noise): one set; an old noise file of another log is not left behind
    write_files_atomic(log_files(out, log, truth, tpath, noise))
    if noise is None:
        remove(noise_file)            # an old noise file of another log: not left beside this one
    summary = {"scene": scene.name, "log": str(out), "truth": str(tpath),
               "timing": str(timing_file), "noise": str(noise_file) if noise is not None else None,
               "samples": len(log.t),
               "duration_s": float(log.t[-1]) if len(log.t) else 0.0,
               "contact_samples": int((truth["link"] > 0).sum()), **stats}
    est = summary.get("q_rad_error_estimate")
    if tol is not None and est is not None and not est <= tol:
        summary.setdefault("warnings", []).append(
            f"q_rad_error_estimate {est:.3g} rad exceeds --error-tolerance {tol:g} rad: tighten rtol/atol "
            f"or the step")
    if args.json:
        print_json(summary)
    else:
        print(f"{scene.name}: {summary['samples']} samples, {summary['contact_samples']} in contact "
              f"→ {out} (+ {tpath.name}, {timing_file.name}"
              + (f", {noise_file.name}" if noise is not None else "")
              + f"); {stats.get('integrator')} in {stats['run_time_s']:.2f} s"
              + (f"; integration error ± {stats['q_rad_error_estimate']:.2g} rad"
                 if "q_rad_error_estimate" in stats else ""),
              file=sys.stdout)
        for w in summary.get("warnings", []):
            print(f"warning: {w}", file=sys.stderr)
    return 0
