"""`torquebench sweep SCENE.toml --vary KEY=V1,V2 ... --executor local|processes:N|dask://HOST:PORT`."""

from __future__ import annotations

from pathlib import Path

HELP = "run a scene over a grid of varied keys (process pool, or a Dask cluster)"
EXAMPLES = """\
torquebench sweep scenes/paper_floating_link2.toml --vary sensors.seed=1,2,3,4 --json
"""


def add_arguments(parser) -> None:
    parser.add_argument("scene", type=Path, help="scene TOML")
    parser.add_argument("--vary", action="append", required=True, metavar="KEY=V1,V2",
                        help="dotted scene key and its values (repeatable: the grid is their product)")
    parser.add_argument("--only", nargs="+", metavar="OUTPUT", default=None, help="outputs per point")
    parser.add_argument("--executor", default="processes:2",
                        help="local, processes:N (default processes:2) or dask://HOST:PORT")
    parser.add_argument("--cache-dir", type=Path, default=None, help="cache directory")
    parser.epilog = (parser.epilog or "") + ("\nExit code 2 when any point failed (the other points are "
                                             "still printed).")


def run(args) -> int:
    from torquebench.io import print_json
    from torquebench.scenes import scene_path
    from torquebench.sweep import parse_vary, run_sweep

    path = scene_path(str(args.scene))
    info = {}
    rows = run_sweep(path, parse_vary(args.vary), args.only, args.executor,
                     str(args.cache_dir) if args.cache_dir else None, info=info,
                     progress=not args.json)
    failed = [r for r in rows if "error" in r]
    if args.json:
        print_json({"scene": str(path), "executor": args.executor, "points": rows,
                    "failed_points": len(failed), "shared_stages": info.get("shared_stages", [])})
        _exit_on_failures(rows)
        return 0
    for r in rows:
        pt = ", ".join(f"{k}={v}" for k, v in r["point"].items())
        if "error" in r:
            print(f"{pt}: FAILED: {r['error']}")
            continue
        me = r["result"].get("measured", {}).get("dynamic", {}).get("position_error_rms_m")
        pr = r["result"].get("predicted", {}).get("dynamic", {}).get("position_rms_m")
        f = (lambda v: f"{v * 1e3:.2f} mm" if v is not None else "—")   # noqa: E731
        print(f"{pt}: measured RMS |p| err {f(me)}, predicted {f(pr)} (dynamic)")
    _exit_on_failures(rows)
    return 0


def _exit_on_failures(rows, what: str = "sweep") -> None:
    """Exit 2 (one line) when any point failed: the rows were printed, the run is not a success."""
    import sys

    from torquebench.sweep import failed_points

    msg = failed_points(rows, what)
    if msg:
        sys.stdout.flush()
        from userio.errors import InputError
        raise InputError(msg.split(": ", 1)[1] if msg.startswith(what) else msg)
