"""`torquebench simulate SCENE.toml --out LOG.csv`: run a scene, write the log and its truth."""

from __future__ import annotations

import sys
import time
from pathlib import Path

from torquebench.errors import InputError

HELP = "simulate a scene file: write LOG.csv (DESIGN.md log format) and LOG.truth.csv beside it"


def add_arguments(parser) -> None:
    parser.add_argument("scene", type=Path, help="scene TOML file (e.g. scenes/paper_floating_link1.toml)")
    parser.add_argument("--out", type=Path, required=True, help="log CSV to write")
    parser.add_argument("--integrator", default=None,
                        help="override the scene's integrator (RK45, DOP853, Radau, BDF, LSODA, RK4)")
    parser.add_argument("--seed", type=int, default=None, help="override the sensor-noise seed")
    parser.add_argument("--duration", type=float, default=None, help="override duration_s (dynamic scenes)")
    parser.add_argument("--max-run-time", type=float, default=600.0, metavar="S",
                        help="refuse a run predicted (or found) to take longer than S seconds (default 600)")
    parser.add_argument("--error-tolerance", type=float, default=None, metavar="RAD",
                        help="warn when the integration error estimate (q_rad_error_estimate) exceeds RAD")


def truth_path(out: Path) -> Path:
    """LOG.csv → LOG.truth.csv."""
    return out.with_name(out.stem + ".truth" + (out.suffix or ".csv"))


def run_scene(scene, seed=None, integrator=None, duration=None, max_run_time_s=600.0):
    """(SensorLog, truth dict, stats) of a dynamic or static scene."""
    from dataclasses import replace

    from estimator.sim import simulate
    from estimator.sim.static import static_hold_log
    import numpy as np

    if scene.sim is not None:
        cfg = scene.sim
        if seed is not None:
            cfg = replace(cfg, sensors=replace(cfg.sensors, seed=seed))
        if integrator is not None:
            from estimator.sim.config import INTEGRATORS
            if integrator not in INTEGRATORS:
                raise InputError(f"--integrator: must be one of {', '.join(INTEGRATORS)}, got {integrator!r}")
            cfg = replace(cfg, integrator=integrator)
        if duration is not None:
            if not (duration > 0 and duration < float("inf")):
                raise InputError(f"--duration: must be > 0, got {duration}")
            cfg = replace(cfg, duration_s=duration)
        res = simulate(cfg, max_run_time_s=max_run_time_s)
        return res.log, res.truth, res.stats
    st = scene.static
    sensors = st.sensors if seed is None else replace(st.sensors, seed=seed)
    start = time.perf_counter()
    pts = st.points
    log, truth, _ = static_hold_log(st.robot, np.array([p.q_rad for p in pts]),
                                    np.array([p.link for p in pts]), np.array([p.alpha for p in pts]),
                                    np.array([p.force_N for p in pts]), sensors, st.hold_s,
                                    tare_s=0.3)
    return log, truth, {"integrator": "static", "run_time_s": time.perf_counter() - start,
                        "points": len(pts)}


def run(args) -> int:
    from estimator.sim.output import log_csv, truth_csv
    from torquebench.io import print_json, write_text_atomic
    from torquebench.scenes import load_scene

    scene = load_scene(args.scene)
    out, tpath = Path(args.out), truth_path(Path(args.out))
    inputs = {args.scene.resolve()}
    if scene.sim is not None or scene.static is not None:
        pass
    for p in (out, tpath):
        if p.resolve() in inputs or p.suffix == ".toml":
            raise InputError(f"--out: {p} is an input (the scene file); refusing to overwrite it")
    if not out.parent.exists():
        raise InputError(f"--out: directory {out.parent} does not exist")
    tol = getattr(args, "error_tolerance", None)
    if tol is not None and not tol > 0:
        raise InputError(f"--error-tolerance: must be > 0 rad, got {tol}")
    max_run = getattr(args, "max_run_time", 600.0)
    if not (max_run > 0):
        raise InputError(f"--max-run-time: must be > 0 s, got {max_run}")
    log, truth, stats = run_scene(scene, args.seed, args.integrator, args.duration,
                                   max_run)
    write_text_atomic(out, log_csv(log))
    write_text_atomic(tpath, truth_csv(truth))
    summary = {"scene": scene.name, "log": str(out), "truth": str(tpath), "samples": len(log.t),
               "duration_s": float(log.t[-1]) if len(log.t) else 0.0,
               "contact_samples": int((truth["link"] > 0).sum()), **stats}
    tol = getattr(args, "error_tolerance", None)
    est = summary.get("q_rad_error_estimate")
    if tol is not None and est is not None and not est <= tol:
        summary.setdefault("warnings", []).append(
            f"q_rad_error_estimate {est:.3g} rad exceeds --error-tolerance {tol:g} rad: tighten rtol/atol "
            f"or the step")
    if args.json:
        print_json(summary)
    else:
        print(f"{scene.name}: {summary['samples']} samples, {summary['contact_samples']} in contact "
              f"→ {out} (+ {tpath.name}); {stats.get('integrator')} in {stats['run_time_s']:.2f} s"
              + (f"; integration error ± {stats['q_rad_error_estimate']:.2g} rad"
                 if "q_rad_error_estimate" in stats else ""),
              file=sys.stdout)
        for w in summary.get("warnings", []):
            print(f"warning: {w}", file=sys.stderr)
    return 0
