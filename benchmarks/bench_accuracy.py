"""The measurements behind reports/error_vs_runtime.md, as one JSON document on stdout.

    python benchmarks/bench_accuracy.py [--quick] [--only NAME ...] [--write-report DIR]
    python benchmarks/bench_accuracy.py --only fem [--fem-meshers gmsh tetgen adaptive scikit-fem]
                                        [--fem-rows OLD.json ...] [--splice-fem-section FILE.md]

Runs every error-vs-run-time sweep (simulators, calibration, uncertainty propagation, the flexure
FEM: gmsh P1 × 6 and P2 × 5 mesh levels, tetgen P2 × 4 and the adaptive default at 3–4 --rtol on 2 geometries, scikit-fem P2 × 2 on
the paper disc and × 1 on the thick one, ≈ 17 min measured on a loaded 2-core machine) and prints the rows (setting, wall time, error) of
each; --write-report also writes reports/error_vs_runtime.md with every section (which runs the
sweeps again). --splice-fem-section replaces only the flexure FEM section of an existing
error_vs_runtime.md (and its PNGs, beside it) with the one built from this run's FEM rows, leaving
the other sections as they are; --fem-rows adds the FEM rows of an earlier run's JSON output (e.g.
the gmsh levels, when this run measures only --fem-meshers tetgen scikit-fem). Timings are wall time
on whatever machine runs it: compare them within one run, never against a number from another machine.
"""

from __future__ import annotations

import argparse
import json
import platform
import sys
from datetime import datetime, timezone
from pathlib import Path


def splice_fem_section(md: Path, rows: list[dict], seconds: float, quick: bool = False, runs: int = 1) -> list[Path]:
    """Replace the flexure FEM section of ``md`` (from its "## Flexure FEM" heading through the
    "_(section built in … s)_" line after it) with the one built from ``rows`` (measured in ``runs``
    separate runs: said in the section, since the machine's load differs between them)."""
    from torquebench.reports import fem
    from userio.files import write_text_atomic

    text = md.read_text()
    start = text.index("\n## Flexure FEM") + 1
    end = text.index("_(section built in", start)
    end = text.index("\n", end) + 1 if "\n" in text[end:] else len(text)
    lines, pngs = fem.fem_section(rows, md.parent, quick)
    if runs > 1:
        lines[3:3] = ["", f"These rows were measured in {runs} separate runs, then merged (`--fem-rows`), "
                      "on a shared machine whose load varied between them: compare wall times across those "
                      "runs (here: across meshers) only to within about a factor of 2.", ""]
    new = "\n".join(lines + [f"_(section built in {seconds:.1f} s)_", ""])
    write_text_atomic(md, text[:start] + new + text[end:])
    return [md, *pngs]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="reduced sweeps (~30 s)")
    ap.add_argument("--only", nargs="+", default=None, choices=("simulators", "calibration", "propagation", "fem"),
                    help="run only these sweeps")
    ap.add_argument("--write-report", type=Path, default=None, metavar="DIR",
                    help="also write error_vs_runtime.md + PNGs into DIR")
    ap.add_argument("--fem-meshers", nargs="+", default=None, choices=("gmsh", "tetgen", "adaptive", "scikit-fem"),
                    help="FEM sweep: only these meshers (default: all)")
    ap.add_argument("--fem-rows", nargs="+", type=Path, default=(), metavar="JSON",
                    help="FEM sweep: add the rows of earlier runs' JSON output")
    ap.add_argument("--splice-fem-section", type=Path, default=None, metavar="MD",
                    help="replace the flexure FEM section of this error_vs_runtime.md with this run's")
    args = ap.parse_args(argv)
    from torquebench.reports import error_vs_runtime as evr

    out = {"machine": f"{platform.node()} {platform.machine()} Python {platform.python_version()}",
           "date_utc": datetime.now(timezone.utc).isoformat(timespec="seconds"), "quick": args.quick}
    from torquebench.reports import fem

    def fem_rows(quick):
        import time

        start = time.perf_counter()
        rows = fem.fem_levels(quick, meshers=args.fem_meshers or fem.MESHERS)
        seconds = time.perf_counter() - start
        for old in args.fem_rows:            # their sweep time: as recorded, else the sum of their rows' wall times
            fem_old = json.loads(old.read_text())["fem"]
            rows += [{"mesher": "gmsh", **r} for r in fem_old["rows"]]
            seconds += fem_old["info"].get("sweep_s", sum(r["time_s"] for r in fem_old["rows"]))
        refs = {f"{g}: {k}": v for (g, k), v in fem._references(rows).items()}
        return rows, {"references": refs, "sweep_s": seconds}

    for name, fn in (("simulators", evr.simulator_rows), ("calibration", evr.calibration_rows),
                     ("propagation", evr.propagation_rows), ("fem", fem_rows)):
        if args.only and name not in args.only:
            continue
        rows, info = fn(args.quick)
        out[name] = {"rows": rows, "info": info}
    if args.splice_fem_section:
        if "fem" not in out:
            ap.error("--splice-fem-section needs the fem sweep")
        out["written"] = [str(p) for p in splice_fem_section(args.splice_fem_section, out["fem"]["rows"],
                                                             out["fem"]["info"]["sweep_s"], args.quick,
                                                             runs=1 + len(args.fem_rows))]
    if args.write_report:
        out["written"] = [str(p) for p in evr.build(args.write_report, quick=args.quick)]
    json.dump(out, sys.stdout, indent=1, default=float)
    print()
    return 0


if __name__ == "__main__":
    sys.exit(main())
