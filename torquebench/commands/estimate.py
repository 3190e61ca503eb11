"""`torquebench estimate LOG.csv`: contact detection, isolation and localization on a sensor log."""

from __future__ import annotations

import math
from pathlib import Path

HELP = "estimate contacts (link, α, force, point) sample by sample from a sensor log CSV"
EXAMPLES = """\
torquebench estimate examples/leg_poke/leg_poke.csv
torquebench estimate examples/sim/paper_fixed_link2.csv --method paper --out out/fixed_link2_estimate.csv --json
"""


def _positive(text: str) -> float:
    import argparse

    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not math.isfinite(value) or value <= 0:
        raise argparse.ArgumentTypeError(f"must be a finite number > 0, got {text!r}")
    return value


def _count(text: str) -> int:
    import argparse

    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number, got {text!r}") from None
    if value < 0:
        raise argparse.ArgumentTypeError(f"must be ≥ 0, got {text!r}")
    return value


def add_arguments(parser) -> None:
    parser.add_argument("log", type=Path, metavar="LOG.csv", help="sensor log CSV: t,[x,z,theta,]q1,q2,[dx,dz,dtheta,]dq1,dq2,tau1,tau2,Fx,Fz,My in SI units (docs/conventions.md)")
    parser.add_argument("--robot", type=Path, default=None,
                        help="robot TOML (default: robots/paper_leg.toml)")
    parser.add_argument("--method", choices=["paper", "dynamic"], default="dynamic",
                        help="localization: 'dynamic' (observer residual, least squares; default) "
                             "or 'paper' (eqs. 6-9, quasi-static)")
    parser.add_argument("--gain", type=_positive, default=100.0, metavar="K",
                        help="observer gain K in 1/s on every row (default: %(default)s)")
    parser.add_argument("--threshold", type=_positive, default=0.06, metavar="EPS",
                        help="detection threshold on the residual norm ||r|| (default: %(default)s)")
    parser.add_argument("--debounce", type=_count, default=0, metavar="N",
                        help="samples ||r|| must stay above EPS before a contact is declared (default: %(default)s)")
    parser.add_argument("--stance-foot", action="store_true",
                        help="the foot (last link, alpha=1) is an expected contact, estimated jointly")
    parser.add_argument("--force", action="store_true", help="replace an existing --out file")
    parser.add_argument("--out", type=Path, default=None, metavar="OUT.csv",
                        help="write t,contact,link,alpha,Fx,Fz,px,pz,rnorm per sample (s, -, -, -, N, N, m, m, -) to this CSV; its directory is created, an existing file is kept unless --force")


def run(args) -> int:
    import time

    from estimator.log import read_log
    from estimator.pipeline import estimate
    from estimator.robot import PAPER_LEG_TOML, load_robot
    from torquebench.errors import InputError
    from torquebench.io import atomic_path, print_json

    start = time.perf_counter()
    if args.out is not None:
        try:
            same = args.out.resolve() == args.log.resolve()
        except OSError:
            same = False
        if same:
            raise InputError(f"--out {args.out}: is the input log; refusing to overwrite it")
    from torquebench.outputs import prepare_file
    prepare_file(args.out, "--out", force=args.force, inputs=(args.log, args.robot))
    robot = load_robot(args.robot or PAPER_LEG_TOML)
    log = read_log(args.log, robot)
    result = estimate(robot, log, method=args.method, gain_per_s=args.gain,
                      threshold=args.threshold, debounce=args.debounce,
                      expected_contacts="foot" if args.stance_foot else None)
    if args.out is not None:
        with atomic_path(args.out) as tmp:
            result.to_frame().to_csv(tmp, index=False, float_format="%.9g", na_rep="NaN")
    elapsed = time.perf_counter() - start
    summary = {"log": str(args.log), "robot": robot.name, "gain_per_s": args.gain,
               "threshold": args.threshold, **result.summary(),
               "skipped_lines": log.skipped_lines[:20].tolist(), "run_time_s": elapsed}
    if args.out is not None:
        summary["out"] = str(args.out)
    if args.json:
        print_json(summary)
        return 0
    print(f"{args.log}: {summary['samples']} samples ({summary['skipped_samples']} skipped for NaN/inf), "
          f"method {args.method}, {summary['contact_samples']} in contact, {elapsed:.2f} s")
    for iv in summary["intervals"]:
        print(f"  contact {iv['t_start_s']:.4f}-{iv['t_end_s']:.4f} s: link {iv['link']}, "
              f"alpha {iv['alpha']:.3f}, F = ({iv['Fx_N']:.3f}, {iv['Fz_N']:.3f}) N, "
              f"p = ({iv['px_m']:.4f}, {iv['pz_m']:.4f}) m")
    if args.out is not None:
        print(f"wrote {args.out}")
    return 0
