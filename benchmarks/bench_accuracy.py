"""The measurements behind reports/error_vs_runtime.md, as one JSON document on stdout.

    python benchmarks/bench_accuracy.py [--quick] [--only NAME ...] [--write-report DIR]

Runs every error-vs-run-time sweep (simulators, calibration, uncertainty propagation, the flexure
FEM: P1 × 6 and P2 × 5 mesh levels × 2 geometries, 20 min measured on a loaded 2-core machine) and prints the rows
(setting, wall time, error) of each; --write-report also writes reports/error_vs_runtime.md with
every section (which runs the sweeps again). Timings are wall time on whatever machine runs it: compare
them within one run, never against a number from another machine.
"""

from __future__ import annotations

import argparse
import json
import platform
import sys
from datetime import datetime, timezone
from pathlib import Path


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="reduced sweeps (~30 s)")
    ap.add_argument("--only", nargs="+", default=None, choices=("simulators", "calibration", "propagation", "fem"),
                    help="run only these sweeps")
    ap.add_argument("--write-report", type=Path, default=None, metavar="DIR",
                    help="also write error_vs_runtime.md + PNGs into DIR")
    args = ap.parse_args(argv)
    from torquebench.reports import error_vs_runtime as evr

    out = {"machine": f"{platform.node()} {platform.machine()} Python {platform.python_version()}",
           "date_utc": datetime.now(timezone.utc).isoformat(timespec="seconds"), "quick": args.quick}
    from torquebench.reports import fem

    def fem_rows(quick):
        rows = fem.fem_levels(quick)
        refs = {f"{g}: {k}": v for (g, k), v in fem._references(rows).items()}
        return rows, refs

    for name, fn in (("simulators", evr.simulator_rows), ("calibration", evr.calibration_rows),
                     ("propagation", evr.propagation_rows), ("fem", fem_rows)):
        if args.only and name not in args.only:
            continue
        rows, info = fn(args.quick)
        out[name] = {"rows": rows, "info": info}
    if args.write_report:
        out["written"] = [str(p) for p in evr.build(args.write_report, quick=args.quick)]
    json.dump(out, sys.stdout, indent=1, default=float)
    print()
    return 0


if __name__ == "__main__":
    sys.exit(main())
