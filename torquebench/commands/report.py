"""`torquebench report`: regenerate reports/ (Markdown + PNG) from every report builder."""

from __future__ import annotations

import importlib
import os
import pkgutil
import sys
import time
from pathlib import Path

import torquebench.reports
from userio.errors import InputError

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


#: where `report` keeps how long each area took the last time it rebuilt the shipped reports
TIMES_FILE = "build_times.json"


def describe(module_name: str) -> str:
    """The first sentence of a builder's docstring, without its ``reports/x.md:`` prefix."""
    import ast
    import importlib.util

    spec = importlib.util.find_spec(module_name)
    doc = ast.get_docstring(ast.parse(Path(spec.origin).read_text(encoding="utf-8"))) or ""
    import re

    para = " ".join(doc.split("\n\n")[0].split())
    first = re.split(r"(?<!eq)(?<!eqs)(?<!Fig)\. (?=[A-Z(`])", para)[0].rstrip(".") + "."
    if first.startswith("reports/") and ": " in first:
        first = first.split(": ", 1)[1]
    return first[:1].upper() + first[1:]


def recorded_times(reports_dir: Path) -> dict:
    """{area: {"s": seconds, "date": "YYYY-MM-DD"}} of the last rebuild of the shipped reports."""
    import json

    try:
        return json.loads((reports_dir / TIMES_FILE).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return {}


def _listing(areas: dict) -> list[dict]:
    from torquebench.io import REPO_ROOT

    times = recorded_times(REPO_ROOT / "reports")
    return [{"area": a, "description": describe(m),
             "last_build_s": times.get(a, {}).get("s"), "last_build_date": times.get(a, {}).get("date"),
             "last_build_load_1min": times.get(a, {}).get("load_1min"),
             "last_build_cores": times.get(a, {}).get("cores")}
            for a, m in areas.items()]


def _machine(row: dict) -> str:
    """", 1-min load 7.2 on 2 cores" when the build recorded them."""
    load, cores = row.get("last_build_load_1min"), row.get("last_build_cores")
    if load is None:
        return ""
    return f", 1-min load {load:g}" + (f" on {cores} cores" if cores else "")


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
        rows = _listing(areas)
        if args.json:
            print_json({"areas": list(areas), "reports": rows})
            return 0
        for r in rows:
            took = (f"{r['last_build_s']:.0f} s when last built ({r['last_build_date']}{_machine(r)})"
                    if r["last_build_s"] is not None else "not timed yet")
            print(f"{r['area']:17s} {r['description']}\n{'':17s} run time: {took}")
        return 0
    chosen = args.only or list(areas)
    unknown = sorted(set(chosen) - set(areas))
    if unknown:
        raise InputError(f"--only: unknown report area {unknown[0]!r}; known: {', '.join(areas)}")
    from userio.outputs import Outputs

    shipped = args.out_dir is None                 # the repository's reports: regenerated in place
    out_dir = args.out_dir or REPO_ROOT / "reports"
    plan = Outputs(force=args.force)
    plan.directory("--out-dir", out_dir, shipped=shipped, names=[*chosen, "README"])
    plan.check()                                   # user files of a report's name are refused
    with plan.active():                            # every builder's write obeys it
        return _build(args, areas, chosen, out_dir)


def _build(args, areas, chosen, out_dir) -> int:
    from torquebench.io import REPO_ROOT, print_json

    written, timings, loads = {}, {}, {}
    for area in chosen:
        start = time.perf_counter()
        load_start = torquebench.reports.load_1min()
        if sys.stderr.isatty():          # progress for a person watching; a pipe gets only the result
            print(f"report: building {area} ...", file=sys.stderr)
        paths = importlib.import_module(areas[area]).build(out_dir)
        timings[f"{area}_s"] = time.perf_counter() - start
        known = [x for x in (load_start, torquebench.reports.load_1min()) if x is not None]
        loads[area] = max(known) if known else None
        written[area] = [str(p) for p in paths]
    from torquebench.reports_index import write_index
    index = write_index(out_dir, list(areas))
    if out_dir == REPO_ROOT / "reports":           # the shipped reports: keep how long each took
        import datetime
        import json

        from userio.files import write_text_atomic

        times = recorded_times(out_dir)
        today = datetime.date.today().isoformat()
        times.update({a: {"s": round(timings[f"{a}_s"], 1), "date": today, "load_1min": loads[a],
                          "cores": os.cpu_count()} for a in written})
        write_text_atomic(out_dir / TIMES_FILE, json.dumps(times, indent=1, sort_keys=True) + "\n")
    if args.json:
        print_json({"written": written, "index": str(index), "build_time_s": timings})
    else:
        for area, paths in written.items():
            print(f"{area}: " + ", ".join(paths))
        print(f"index: {index}")
    return 0
