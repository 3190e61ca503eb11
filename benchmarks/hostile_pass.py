"""An adversarial pass over all 17 subcommands: a few hundred hostile inputs per class, each run
as a real `torquebench` process in a fresh work directory, and its outcome classified.

    python benchmarks/hostile_pass.py [--seed 1] [--jobs 2] [--only CLASS] [--match TEXT] [--limit N] [--json OUT]

Classes of input (each generated from a seed, so a second seed gives fresh inputs of the same kinds):
  paths      outputs that are inputs under another name (sidecars, symlinks, hard links, ``..``),
             existing files without --force, scene names that are paths, cache dirs with user files,
             .part captures that are symlinks, directories and device nodes as outputs
  nonsense   logs in wrong units or with swapped/dead channels, absurd options and file fields
  oserror    read-only or full file systems, device/directory inputs, unresolvable hosts,
             hash-valid files with wrong types
  runaway    huge headers/files/devices, huge sizes (walkers, rows, n_avg, thin walls, gains)
  interrupt  Ctrl-C (SIGINT) part-way through long commands
  valid      controls: ordinary inputs that must still work (exit 0)

Outcomes (first that applies):
  runaway     over the time limit (--timeout) or the memory cap (--max-rss-gb): killed
  traceback   a Python traceback on stderr, "internal error", exit 1, or killed by a signal
  data_loss   a file that existed before changed or vanished (except a named output replaced with
              --force), or a file appeared outside the case's work directory
  unclear     exit 2 with more or less than one line on stderr, or "not found" for a path that
              exists; an interrupt that does not end with exit 130 and one line (after the run's own
              progress lines)
  silent      nonsense input answered with exit 0 and no "warning" anywhere in the output
  refused_valid  a control case that did not exit 0
  ok          anything else (exit 2 with one line; exit 0 with a warning; a control that worked)

Mounts a small read-only and a full tmpfs when it can (root with CAP_SYS_ADMIN), else skips those
cases. Prints the counts per class × outcome, and writes every case's record with --json.
"""

from __future__ import annotations

import argparse
import json
import random
import shutil
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

from hostile_cases import common
from hostile_cases.common import build_fixture
from hostile_cases.identify_3d import gen_identify_and_3d
from hostile_cases.interrupt import gen_interrupt
from hostile_cases.nonsense import gen_nonsense
from hostile_cases.oserror import gen_oserror, mount_fs, unmount
from hostile_cases.paths import gen_paths
from hostile_cases.runaway import gen_runaway
from hostile_cases.runner import run_case
from hostile_cases.valid import gen_valid


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--only", action="append", default=None)
    ap.add_argument("--limit", type=int, default=None, help="at most N cases per class")
    ap.add_argument("--match", action="append", default=None, help="only cases whose name contains this text (repeatable: any)")
    ap.add_argument("--timeout", type=float, default=90.0)
    ap.add_argument("--max-rss-gb", type=float, default=4.0)
    ap.add_argument("--json", type=Path, default=None)
    ap.add_argument("--list", action="store_true")
    ap.add_argument("--repo", type=Path, default=None,
                    help="the checkout to test (default: this one), e.g. an exported older commit")
    args = ap.parse_args(argv)
    if args.repo is not None:
        common.REPO = args.repo.resolve()
    sys.path.insert(0, str(common.REPO))
    rng = random.Random(args.seed)
    base = Path(tempfile.mkdtemp(prefix="hostile_pass_"))
    mounts = mount_fs(base)
    try:
        fixture = build_fixture(base)
        cases = (gen_paths(rng) + gen_nonsense(rng) + gen_oserror(rng, mounts) + gen_runaway(rng)
                 + gen_interrupt(rng) + gen_valid(rng) + gen_identify_and_3d(rng))
        cases = [c for c in cases if not c.needs or c.needs in mounts]
        if args.only:
            cases = [c for c in cases if c.cls in args.only]
        if args.match:
            cases = [c for c in cases if any(m in c.name for m in args.match)]
        if args.limit:
            per = {}
            keep = []
            for c in cases:
                per[c.cls] = per.get(c.cls, 0) + 1
                if per[c.cls] <= args.limit:
                    keep.append(c)
            cases = keep
        if args.list:
            for c in cases:
                print(c.cls, "|", c.name, "|", " ".join(c.argv))
            return 0
        print(f"hostile pass: {len(cases)} cases (seed {args.seed}, {args.jobs} jobs) in {base}", file=sys.stderr)
        common.SHARED_CACHE = base / "shared-cache"
        common.SHARED_CACHE.mkdir(exist_ok=True)
        records = []
        t0 = time.perf_counter()
        with ThreadPoolExecutor(args.jobs) as pool:
            futs = [pool.submit(run_case, c, base, fixture, args.timeout, args.max_rss_gb * 2 ** 30, i)
                    for i, c in enumerate(cases)]
            for i, f in enumerate(futs):
                r = f.result()
                records.append(r)
                if r["outcome"] != "ok":
                    print(f"[{i + 1}/{len(cases)}] {r['outcome']:>14s}  {r['class']:>9s}  {r['name']}  "
                          f"(exit {r['exit']}, {r['time_s']} s) {r['changed'][:2]} "
                          f"{(r['stderr'].strip().splitlines() or [''])[-1][:160]}", file=sys.stderr)
        total = time.perf_counter() - t0
    finally:
        unmount(mounts)
        if args.list:
            shutil.rmtree(base, ignore_errors=True)
    table = {}
    for r in records:
        table.setdefault(r["class"], {}).setdefault(r["outcome"], 0)
        table[r["class"]][r["outcome"]] += 1
    outcomes = ["ok", "silent", "data_loss", "traceback", "runaway", "unclear", "refused_valid"]
    print(f"{'class':10s} {'cases':>6s} " + " ".join(f"{o:>13s}" for o in outcomes))
    for cls, row in table.items():
        print(f"{cls:10s} {sum(row.values()):6d} " + " ".join(f"{row.get(o, 0):13d}" for o in outcomes))
    allrows = {o: sum(row.get(o, 0) for row in table.values()) for o in outcomes}
    print(f"{'total':10s} {len(records):6d} " + " ".join(f"{allrows[o]:13d}" for o in outcomes))
    print(f"wall time {total:.0f} s (load: shared machine)")
    if args.json:
        args.json.write_text(json.dumps({"seed": args.seed, "table": table, "records": records}, indent=1))
    shutil.rmtree(base, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
