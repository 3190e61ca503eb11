"""`torquebench report`: regenerate reports/ (Markdown + PNG) from every report builder."""

from __future__ import annotations

import importlib
import pkgutil
import sys
import time
from pathlib import Path

import torquebench.reports
from torquebench.errors import InputError

HELP = "regenerate the Markdown + PNG reports in reports/ (all areas, or --only AREA)"
EXAMPLES = """\
torquebench report --list
torquebench report --only bridge --out-dir out/reports
"""


def builders() -> dict:
    """{area: module} for every ``torquebench/reports/<area>.py`` (each has ``build(out_dir)``)."""
    return {info.name: f"torquebench.reports.{info.name}"
            for info in sorted(pkgutil.iter_modules(torquebench.reports.__path__), key=lambda i: i.name)
            if not info.name.startswith("_")}


def add_arguments(parser) -> None:
    parser.add_argument("--out-dir", type=Path, default=None,
                        help="directory to write the reports to, created if missing; reports are regenerated in place (default: the repository's reports/)")
    parser.add_argument("--only", action="append", metavar="AREA",
                        help="build only this area (repeatable; default: all); see --list")
    parser.add_argument("--list", action="store_true", help="list the report areas and exit")
    parser.add_argument("--force", action="store_true",
                        help="replace report files in --out-dir that `report` did not write there")


def run(args) -> int:
    from torquebench.io import REPO_ROOT, print_json

    areas = builders()
    if args.list:
        if args.json:
            print_json({"areas": list(areas)})
        else:
            print("\n".join(areas))
        return 0
    chosen = args.only or list(areas)
    unknown = sorted(set(chosen) - set(areas))
    if unknown:
        raise InputError(f"--only: unknown report area {unknown[0]!r}; known: {', '.join(areas)}")
    from torquebench.outputs import Outputs, foreign_files

    shipped = args.out_dir is None                 # the repository's reports: regenerated in place
    out_dir = args.out_dir or REPO_ROOT / "reports"
    plan = Outputs(force=args.force)
    plan.directory("--out-dir", out_dir, shipped=shipped)
    plan.check()
    if not shipped:
        clash = foreign_files(out_dir, [*chosen, "README"], plan.force)
        if clash:
            raise InputError(f"--out-dir: {clash[0]} exists and was not written by `report` "
                             f"({len(clash)} such file(s) with a report's name); add --force to "
                             "replace them or choose another directory")
    with plan.active():                            # every builder's write obeys it
        return _build(args, areas, chosen, out_dir)


def _build(args, areas, chosen, out_dir) -> int:
    from torquebench.io import print_json

    written, timings = {}, {}
    for area in chosen:
        start = time.perf_counter()
        print(f"report: building {area} ...", file=sys.stderr)
        paths = importlib.import_module(areas[area]).build(out_dir)
        timings[f"{area}_s"] = time.perf_counter() - start
        written[area] = [str(p) for p in paths]
    from torquebench.reports_index import write_index
    index = write_index(out_dir, list(areas))
    if args.json:
        print_json({"written": written, "index": str(index), "build_time_s": timings})
    else:
        for area, paths in written.items():
            print(f"{area}: " + ", ".join(paths))
        print(f"index: {index}")
    return 0
