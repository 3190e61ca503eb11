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
    out_dir = args.out_dir or REPO_ROOT / "reports"
    from torquebench.outputs import prepare_dir
    prepare_dir(out_dir, "--out-dir")
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
