"""`torquebench run SCENE.toml`: the stage graph (torquebench.pipeline) on one scene.

Built backwards from the requested outputs (``--only``, else the scene's ``[outputs] want``);
``--explain`` prints each stage with run / skip / cached and the reason, without running.
"""

from __future__ import annotations

import sys
from pathlib import Path

HELP = "run a scene through the stage graph (only the stages its outputs need)"
EXAMPLES = """\
torquebench run scenes/end_to_end.toml --explain
torquebench run scenes/end_to_end.toml --json
"""


def add_arguments(parser) -> None:
    parser.add_argument("scene", type=Path, help="scene TOML (e.g. scenes/end_to_end.toml)")
    parser.add_argument("--only", nargs="+", metavar="OUTPUT", default=None,
                        help="outputs to compute (localization_error, predicted_error, calibration, "
                             "sensitivity, noise_budget, flexure, estimates, report; a 3-D scene: "
                             "spatial_log, spatial_estimates, spatial_localization_error, "
                             "spatial_predicted_error) (default: the scene's [outputs] want)")
    parser.add_argument("--explain", action="store_true", help="print the plan; run nothing")
    parser.add_argument("--force", action="store_true", help="ignore cached results")
    parser.add_argument("--overwrite", action="store_true",
                        help="replace report files in the scene's [outputs] dir that torquebench did "
                             "not write (default: refuse, before any work)")
    parser.add_argument("--seed", type=int, default=None, help="sensor-noise seed (default: the scene's)")
    parser.add_argument("--cache-dir", type=Path, default=None,
                        help="cache directory (default $TORQUEBENCH_CACHE or .torquebench-cache)")


def run(args) -> int:
    from torquebench import formatting as fmt
    from torquebench.stages.summary import summarize
    from torquebench import pipeline as P
    from torquebench.cache import Cache
    from torquebench.io import print_json
    from torquebench.scenes import load_scene, scene_path

    from estimator.spatial.scene import is_spatial_scene
    from torquebench.outputs import run_plan
    from userio.errors import seed

    seed(args.seed)
    if is_spatial_scene(scene_path(str(args.scene))):       # a URDF robot: the 3-D scene runner
        return _run_3d(args)
    scene = load_scene(scene_path(str(args.scene)))
    cache = Cache(args.cache_dir)
    if args.explain:
        return _explain(scene, args, cache)
    with run_plan(scene, args.only, force=args.overwrite).active():     # inputs kept, reports checked
        arts, timing = P.execute(scene, args.only, cache, args.seed, args.force)
    out = {"scene": scene.name, **summarize(arts),
           "stages": [{"stage": n, "action": a, "time_s": t} for n, a, t in timing]}
    if args.json:
        print_json(out)
        return 0
    for n, a, t in timing:
        print(f"  {n:20s} {a:7s} {t:7.2f} s", file=sys.stderr)
    if "flexure" in out:
        print(f"flexure: {fmt.flexure_text(out['flexure'])}")
        for w in out["flexure"].get("warnings", []):
            print(f"WARNING: flexure: {w}")
    if "chain" in arts:
        print(f"sensor: {fmt.sensor_text(arts['chain'])}")
    if "calibration" in arts:
        print(f"calibration: {fmt.calibration_text(arts['calibration'])}")
    if out.get("residual_noise_source"):
        print(f"detector noise: {out['residual_noise_source']}")
    if "measured" in out or "predicted" in out:
        print(f"{'method':8s} {'measured RMS |p| err':>21s} {'predicted RMS':>22s} {'predicted p95':>14s}")
        for m in P.METHODS:
            me, pred, p95 = fmt.error_cells(out.get("measured"), out.get("predicted"), m)
            print(f"{m:8s} {me:>21s} {pred:>22s} {p95:>14s}")
    if "report" in out:
        r = out["report"]
        print(f"report: {r['summary']}" + (f" + views {', '.join(r['areas'])} in {r['dir']}" if r["areas"] else ""))
    if "flagged_samples" in out:
        print(f"saturated/out-of-range samples kept out of detection: {out['flagged_samples']}")
    return 0


def _run_3d(args) -> int:
    """A 3-D scene through its stages (torquebench.stages.spatial): simulate, estimate, measured
    against the truth, predicted at the pokes."""
    from torquebench.cache import Cache
    from torquebench.io import print_json
    from torquebench.scenes import scene_path
    from torquebench.spatial_scene import run_scene_stages

    path = scene_path(str(args.scene))
    cache = Cache(args.cache_dir)
    if args.explain:
        from estimator.spatial.scene import load_spatial_scene

        return _explain(load_spatial_scene(path), args, cache)
    out, timing = run_scene_stages(path, seed=args.seed, cache=cache, force=args.force,
                                   outputs=args.only)
    out["stages"] = [{"stage": n, "action": a, "time_s": t} for n, a, t in timing]
    if args.json:
        print_json(out)
        return 0
    for n, a, t in timing:
        print(f"  {n:20s} {a:7s} {t:7.2f} s", file=sys.stderr)
    f = (lambda v: f"{v * 1e3:.3f} mm" if v is not None else "—")   # noqa: E731
    head = f"{out['scene']} ({out['robot']}, URDF)"
    if "measured" in out:
        me = out["measured"]["dynamic"]
        head += (f": {me['contact_samples']} contact samples, link right on "
                 f"{100 * (me['isolation_fraction'] or 0):.1f} %, position RMS "
                 f"{f(me['position_error_rms_m'])} (median {f(me['position_error_median_m'])})")
    if "predicted" in out:
        head += f"; predicted {f(out['predicted']['dynamic']['position_rms_m'])}"
    if "measured" in out:
        me = out["measured"]["dynamic"]
        head += (f"; false alarms {100 * (me['false_alarm_fraction'] or 0):.3f} % of "
                 f"{me['contact_free_samples']} contact-free samples")
    print(f"{head}; {out['run_time_s']:.1f} s")
    return 0


def _explain(scene, args, cache) -> int:
    """``--explain``: the plan of a scene (planar or 3-D), one line (or JSON row) per stage."""
    from torquebench import pipeline as P
    from torquebench.io import print_json

    steps = P.plan(scene, args.only, cache, args.seed, args.force)
    rows = [{"stage": s.stage.name, "action": s.action, "reason": s.reason, "gives": s.stage.gives,
             "needs": list(s.stage.needs), "reads": list(s.stage.reads)} for s in steps]
    if args.json:
        print_json({"scene": scene.name, "stages": rows})
    else:
        for r in rows:
            print(f"{r['stage']:20s} {r['action']:7s} {r['reason']}")
    return 0
