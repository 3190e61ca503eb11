"""`torquebench estimate LOG.csv`: contact detection, isolation and localization on a sensor log."""

from __future__ import annotations

import math
from pathlib import Path

from torquebench.options import floats as _floats, model_uncertainty_option

HELP = "estimate contacts (link, α, force, point) sample by sample from a sensor log CSV"
EXAMPLES = """\
torquebench estimate examples/leg_poke/leg_poke.csv
torquebench estimate examples/sim/paper_fixed_link2.csv --method paper --out out/fixed_link2_estimate.csv --json
torquebench estimate examples/spatial/leg_pokes.csv --robot robots/quadruped_leg.toml
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


def _in_range(rng_name: str):
    """An argparse type: a finite number inside a Range of estimator.limits (unit in the message)."""
    import argparse

    def parse(text: str) -> float:
        from estimator import limits

        value = _positive(text)
        why = getattr(limits, rng_name).problem(value)
        if why:
            raise argparse.ArgumentTypeError(why)
        return value
    parse.__name__ = "number"
    return parse


def _count(text: str) -> int:
    import argparse

    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number, got {text!r}") from None
    if value < 0:
        raise argparse.ArgumentTypeError(f"must be ≥ 0, got {text!r}")
    return value


def _chunk(text: str) -> int:
    import argparse

    value = _count(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be ≥ 1, got {text!r}")
    return value


def add_arguments(parser) -> None:
    parser.add_argument("log", type=Path, metavar="LOG.csv", help="sensor log: CSV (or Parquet for .parquet) with t,[x,z,theta,]q1,q2,[dx,dz,dtheta,]dq1,dq2,tau1,tau2,Fx,Fz,My in SI units (docs/conventions.md)")
    parser.add_argument("--robot", type=Path, default=None,
                        help="robot TOML (default: robots/paper_leg.toml), or a URDF robot: a .urdf or "
                             "a declaration TOML naming one (robots/quadruped_leg.toml): the 3-D estimator")
    parser.add_argument("--method", choices=["paper", "dynamic"], default="dynamic",
                        help="localization: 'dynamic' (observer residual, least squares; default) "
                             "or 'paper' (eqs. 6-9, quasi-static)")
    parser.add_argument("--gain", type=_in_range("GAIN_RANGE"), default=100.0, metavar="K",
                        help="observer gain K in 1/s on every row (default: %(default)s)")
    parser.add_argument("--threshold", type=_in_range("THRESHOLD_RANGE"), default=None, metavar="EPS",
                        help="use the paper's rule ||r|| > EPS (default for --method paper, EPS 0.06)")
    parser.add_argument("--false-alarm-rate", default="1/h", metavar="RATE",
                        help="dynamic detector: target false alarms, e.g. 1/h (default), 0.01/s, "
                             "1e-6/sample; must be in (0, 1) per sample")
    parser.add_argument("--detector", choices=["chi2", "cusum"], default="chi2",
                        help="dynamic detector on the whitened residual: 'chi2' (per-sample test; "
                             "default) or 'cusum' (sequential; detects small persistent contacts "
                             "more often, ends ~110 ms after them; reports/detection.md) "
                             "(default: %(default)s)")
    parser.add_argument("--quiet-window", default=None, metavar="T0:T1",
                        help="estimate the residual noise from this contact-free stretch (seconds) "
                             "instead of the sensor noise model (which is, in order: these --*-sigma "
                             "options, LOG.noise.toml beside the log, the paper leg's sensors)")
    parser.add_argument("--torque-sigma", default=None, metavar="NM[,NM...]",
                        help="joint torque noise σ per sample, N·m (default 0.005, paper leg)")
    parser.add_argument("--ft-sigma", default=None, metavar="FX,FZ,MY",
                        help="FT sensor noise σ per sample, N, N, N·m (default 0.1,0.1,0.01)")
    parser.add_argument("--velocity-sigma", default=None, metavar="RAD_PER_S",
                        help="joint-rate noise σ per sample (default 0)")
    parser.add_argument("--encoder-counts", default=None, metavar="COUNTS",
                        help="encoder counts per revolution (quantization noise; default 0 = none)")
    parser.add_argument("--model-uncertainty", default=None, metavar="REL|none",
                        help="how far the robot may be from its file, 1σ relative (masses, "
                             "inertias, and centres of mass as a fraction of each link's length): "
                             "the detector's covariance gains the model-error term; 'none' turns "
                             "it off (default: the robot file's [identification] covariance, else "
                             "its [model_uncertainty], else none)")
    parser.add_argument("--debounce", type=_count, default=0, metavar="N",
                        help="samples ||r|| must stay above EPS before a contact is declared (default: %(default)s)")
    parser.add_argument("--stance-foot", action="store_true",
                        help="the foot (last link, alpha=1) is an expected contact, estimated jointly")
    parser.add_argument("--timing", default=None, metavar="instant|mean|delay:SECONDS",
                        help="how every force channel (tau, Fx, Fz, My) was sampled: the value at "
                             "the sample time, the mean over the preceding interval, or a filter "
                             "with this group delay (default: LOG.timing.toml beside the log, "
                             "else instant)")
    parser.add_argument("--out", type=Path, default=None, metavar="OUT.csv",
                        help="write t,contact,link,alpha,Fx,Fz,px,pz,rnorm per sample (s, -, -, -, N, N, m, m, -); "
                             "Parquet for .parquet, else CSV; its directory is created, an existing file is kept unless --force")
    parser.add_argument("--force", action="store_true", help="replace an existing --out file")
    parser.add_argument("--weighting", choices=["whitened", "identity"], default="whitened",
                        help="URDF robots: the localizer's least squares on the residual whitened by "
                             "its no-contact covariance, or unweighted (the planar dynamic method's "
                             "fit; the paper leg as a URDF then reproduces it) (default: %(default)s)")
    parser.add_argument("--png", type=Path, default=None, metavar="OUT.png",
                        help="URDF robots: the robot in 3-D at each contact interval's middle sample, the "
                             "estimated contact and force arrow beside the true one (LOG.truth.csv, if "
                             "there); one picture per interval: OUT.png, OUT_2.png, ...")
    parser.add_argument("--chunk-samples", type=_chunk, default=65536, metavar="N",
                        help="samples read, estimated and written per chunk: memory is bounded by "
                             "this, not by the log's length; results do not depend on it "
                             "(default: %(default)s)")


def _detector_options(args, n_links):
    """(NoiseModel or None, quiet window or None, (rate, unit)) from the options."""
    from estimator.noise import NoiseModel, paper_leg_noise, parse_rate
    from userio.errors import InputError

    rate = parse_rate(args.false_alarm_rate, "--false-alarm-rate")
    if not (math.isfinite(rate[0]) and rate[0] > 0):
        raise InputError(f"--false-alarm-rate: must be > 0, got {args.false_alarm_rate!r}")
    quiet = None
    if args.quiet_window is not None:
        parts = str(args.quiet_window).split(":")
        if len(parts) != 2:
            raise InputError(f"--quiet-window: expected T0:T1 in seconds, got {args.quiet_window!r}")
        quiet = tuple(_floats(p, "--quiet-window", 1)[0] for p in parts)
    given = [args.torque_sigma, args.ft_sigma, args.velocity_sigma, args.encoder_counts]
    if all(v is None for v in given):
        return None, quiet, rate
    base = paper_leg_noise()
    tau = _floats(args.torque_sigma, "--torque-sigma") if args.torque_sigma is not None else base.torque_sigma_Nm
    if len(tau) not in (1, n_links):
        raise InputError(f"--torque-sigma: expected 1 or {n_links} values, got {len(tau)}")
    ft = _floats(args.ft_sigma, "--ft-sigma", 3) if args.ft_sigma is not None else base.ft_sigma
    vel = _floats(args.velocity_sigma, "--velocity-sigma", 1)[0] if args.velocity_sigma is not None else 0.0
    enc = _floats(args.encoder_counts, "--encoder-counts", 1)[0] if args.encoder_counts is not None else 0
    src = "--torque-sigma/--ft-sigma/--velocity-sigma/--encoder-counts"
    return NoiseModel(torque_sigma_Nm=tau, ft_sigma=ft, velocity_sigma_rad_per_s=vel,
                      encoder_counts=enc, source=src), quiet, rate


def _peak_memory_MB() -> float:
    """Peak resident memory of this process so far, MB: VmHWM (Linux; ru_maxrss would carry the
    parent's peak across fork + exec), else ru_maxrss."""
    import resource
    import sys

    try:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1]) / 1024.0
    except OSError:
        pass
    kb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return kb / (1024.0 * 1024.0) if sys.platform == "darwin" else kb / 1024.0


def run(args) -> int:
    import time

    from userio.outputs import Outputs

    start = time.perf_counter()

    plan = Outputs(force=args.force)
    plan.input("LOG.csv", args.log, log=True)           # the log and its side files
    plan.input("--robot", args.robot)
    from estimator.spatial.robot import is_spatial_robot_file

    if args.robot is not None and is_spatial_robot_file(args.robot):   # the URDF it names, too
        from estimator.spatial.robot import load_spatial_robot

        plan.input("--robot's URDF", load_spatial_robot(args.robot).urdf_path)
    plan.file("--out", args.out)
    plan.file("--png", getattr(args, "png", None))       # the first contact's picture (3-D)
    with plan.active():                                 # checked now; every write obeys it
        return _run(args, start)


def _run(args, start) -> int:
    import contextlib
    import time

    from tqdm import tqdm

    from estimator.estimate import open_stream
    from estimator.log_reader import LogReader, prefetch
    from estimator.outframe import BackgroundWriter, FrameWriter
    from estimator.robot import PAPER_LEG_TOML, load_robot
    from userio.errors import InputError
    from torquebench.io import print_json

    from estimator.spatial.robot import is_spatial_robot_file
    if args.robot is not None and is_spatial_robot_file(args.robot):   # a URDF robot: the 3-D path
        from torquebench.spatial_cli import estimate as estimate_3d
        return estimate_3d(args)
    if getattr(args, "png", None) is not None:
        raise InputError("--png: the 3-D contact picture is drawn for URDF robots (--robot LEG.urdf)")
    if getattr(args, "weighting", "whitened") != "whitened":
        raise InputError("--weighting: for URDF robots; the planar dynamic method's fit is unweighted")
    robot = load_robot(args.robot or PAPER_LEG_TOML)
    noise, quiet, rate = _detector_options(args, robot.n_links)
    if noise is None and quiet is None:           # LOG.noise.toml beside the log, if any
        from estimator.log_declarations import read_noise_declaration
        noise = read_noise_declaration(args.log, robot.n_links)
    timing = None
    if args.timing is not None:
        from estimator.timing import uniform
        timing = uniform(args.timing, robot.n_links, "--timing")
    chunk = args.chunk_samples
    reader = LogReader(args.log, robot, chunk_samples=chunk)
    chunks = iter(reader)
    first = next(chunks)                          # the head: the sampling period is known
    from estimator.plausibility import check_head, whole_log_contact

    # the head against the robot's dynamics: unit/channel mix-ups refused, oddities warned about
    found = check_head(robot, first, noise, expected_contact=args.stance_foot)
    stream = open_stream(robot, reader, method=args.method, gain_per_s=args.gain,
                         threshold=args.threshold, debounce=args.debounce,
                         expected_contacts="foot" if args.stance_foot else None, timing=timing,
                         noise=noise, quiet_window=quiet, false_alarm_rate=rate,
                         detector=args.detector, model_uncertainty=model_uncertainty_option(args.model_uncertainty),
                         quiet_chunks=lambda: LogReader(args.log, robot, chunk_samples=chunk))
    with contextlib.ExitStack() as stack:
        writer = None
        if args.out is not None:                  # formatting runs beside the next chunk's work
            writer = BackgroundWriter(stack.enter_context(FrameWriter(args.out)))
            stack.callback(writer.close)
        bar = stack.enter_context(tqdm(unit=" samples", unit_scale=True, disable=None, leave=False,
                                       desc="estimate"))

        def emit(parts):
            for part in parts:
                if writer is not None:
                    writer.write(part)
                bar.update(len(part.t))

        emit(stream.feed(first))
        for c in prefetch(chunks):                # parsing the next chunk overlaps this one
            emit(stream.feed(c))
        emit(stream.finish())
        reader.finish()                           # whole-log plausibility (velocity units)
    est = stream.summary()
    elapsed = time.perf_counter() - start
    summary = {"log": str(args.log), "robot": robot.name, "gain_per_s": args.gain,
               "method": est.pop("method"), "samples": est.pop("samples"),
               "skipped_samples": reader.n_skipped, **est,
               "skipped_lines": reader.skipped_lines[:20].tolist(), "run_time_s": elapsed,
               "chunk_samples": chunk, "peak_memory_MB": _peak_memory_MB()}
    if args.out is not None:
        summary["out"] = str(args.out)
    found += [w for w in [whole_log_contact(summary, found), stream.misfit_warning(str(args.log))] if w]
    found += list(getattr(reader, "plausibility_warnings", []) or []) + reader.constant_channels()
    from estimator.plausibility import attach_warnings

    attach_warnings(summary, found)
    if args.json:
        print_json(summary)
        return 0
    print(f"{args.log}: {summary['samples']} samples ({summary['skipped_samples']} skipped for NaN/inf), "
          f"method {args.method}, {summary['contact_samples']} in contact, {elapsed:.2f} s")
    print(f"  sensor timing: {summary['timing']} ({summary['timing_source']})")
    if "false_alarm_rate_per_s" in summary:
        print(f"  detector: {summary['detector']}, {summary['false_alarm_rate_per_s'] * 3600:.3g} false alarms/h "
              f"({summary['false_alarm_probability_per_sample']:.3g}/sample); residual noise from "
              f"{summary['residual_noise_source']}")
    else:
        print(f"  detector: {summary['detector']}, threshold {summary['threshold']:g}")
    for iv in summary["intervals"]:
        def pm(key, fmt):
            err = iv.get(f"{key}_error_estimate")
            return f"{iv[key]:{fmt}}" + (f" ± {err:{fmt}}" if err is not None else "")
        print(f"  contact {iv['t_start_s']:.4f}-{iv['t_end_s']:.4f} s: link {iv['link']}, "
              f"alpha {pm('alpha', '.3f')}, F = ({pm('Fx_N', '.3f')}, {pm('Fz_N', '.3f')}) N, "
              f"p = ({pm('px_m', '.4f')}, {pm('pz_m', '.4f')}) m")
        if iv.get("error_over_bound") is not None:          # the episode estimate and its bounds
            ps = iv.get("position_bound_per_sample_m")
            print(f"    along the link ± {iv['position_m_error_estimate'] * 1e3:.3f} mm over "
                  f"{iv['episode_samples']} samples; Cramér–Rao bound {iv['position_bound_m'] * 1e3:.3f} mm "
                  f"({iv['error_over_bound']:.2f}×)" + (f", per sample {ps * 1e3:.3f} mm" if ps else ""))
    if args.out is not None:
        print(f"wrote {args.out}")
    return 0
