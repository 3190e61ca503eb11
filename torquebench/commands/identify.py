"""`torquebench identify LOG.csv [LOG2.csv …] --robot ROBOT.toml --out IDENTIFIED.toml`: the robot's
inertial parameters from contact-free logs with motion (estimator.identification), written as a
robot TOML that `estimate`, `propagate` and scenes read unchanged, with an [identification] table
(source logs and their sha256, the parameter covariance, fit statistics)."""

from __future__ import annotations

import math
from pathlib import Path

from userio.errors import InputError
from torquebench.options import DEFAULT_PRIOR, fit_prior
from userio.outputs import sha256_of

HELP = "identify a robot's inertial parameters from contact-free logs; write an identified robot TOML"
EXAMPLES = """\
torquebench identify examples/identification/excitation.csv --robot robots/paper_leg.toml --out out/leg_identified.toml
torquebench identify examples/identification/excitation.csv --out out/leg_id.toml --prior 0.2 --json
"""


def _window(text: str) -> float:
    import argparse

    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected seconds, got {text!r}") from None
    if not (math.isfinite(v) and 0 < v <= 1.0):
        raise argparse.ArgumentTypeError(f"must be in (0, 1] s, got {text!r}")
    return v


def add_arguments(parser) -> None:
    parser.add_argument("logs", type=Path, nargs="+", metavar="LOG.csv",
                        help="contact-free sensor logs with motion (docs/conventions.md), e.g. a "
                             "run of scenes/identification_excitation.toml; each may carry "
                             "LOG.noise.toml and LOG.timing.toml beside it")
    parser.add_argument("--robot", type=Path, default=None,
                        help="the nominal robot TOML (default: robots/paper_leg.toml); a URDF "
                             "robot (LEG.urdf or its declaration TOML) writes IDENTIFIED.urdf too")
    parser.add_argument("--out", type=Path, required=True, metavar="IDENTIFIED.toml",
                        help="identified robot TOML to write; directory created, an existing file "
                             "is kept unless --force")
    parser.add_argument("--force", action="store_true", help="replace an existing --out file")
    parser.add_argument("--prior", type=float, default=None, metavar="REL",
                        help="relative 1σ of the nominal masses and inertias, and of the centres of "
                             "mass as a fraction of each link's length, as the fit's prior "
                             f"(default: the file's [model_uncertainty], else {DEFAULT_PRIOR})")
    parser.add_argument("--window", type=_window, default=0.005, metavar="S",
                        help="length of the momentum-balance windows in s (default: %(default)s)")
    parser.add_argument("--torque-sigma", default=None, metavar="NM[,NM...]",
                        help="joint torque noise σ per sample, N·m (default: LOG.noise.toml, else 0.005)")
    parser.add_argument("--ft-sigma", default=None, metavar="FX,FZ,MY",
                        help="FT sensor noise σ per sample, N, N, N·m (default: LOG.noise.toml, "
                             "else 0.1,0.1,0.01)")
    parser.add_argument("--velocity-sigma", default=None, metavar="RAD_PER_S",
                        help="joint-rate noise σ per sample (default: LOG.noise.toml, else 0)")
    parser.add_argument("--timing", default=None, metavar="instant|mean|delay:SECONDS",
                        help="how every force channel was sampled (default: LOG.timing.toml beside "
                             "each log, else instant)")


def _noise(args, log_path, n_links):
    """(NoiseModel, source) for one log: options, else LOG.noise.toml, else the paper leg's."""
    from estimator.log_declarations import read_noise_declaration
    from estimator.noise import NoiseModel, paper_leg_noise
    from torquebench.options import floats as _floats

    given = [args.torque_sigma, args.ft_sigma, args.velocity_sigma]
    declared = read_noise_declaration(log_path, n_links)
    base = declared or paper_leg_noise()
    if all(v is None for v in given):
        return base
    tau = _floats(args.torque_sigma, "--torque-sigma") if args.torque_sigma is not None \
        else base.torque_sigma_Nm
    if len(tau) not in (1, n_links):
        raise InputError(f"--torque-sigma: expected 1 or {n_links} values, got {len(tau)}")
    ft = _floats(args.ft_sigma, "--ft-sigma", 3) if args.ft_sigma is not None else base.ft_sigma
    vel = _floats(args.velocity_sigma, "--velocity-sigma", 1)[0] if args.velocity_sigma is not None \
        else base.velocity_sigma_rad_per_s
    return NoiseModel(torque_sigma_Nm=tau, ft_sigma=ft, velocity_sigma_rad_per_s=vel,
                      source="--torque-sigma/--ft-sigma/--velocity-sigma")


def _read(args, path: Path, robot):
    """A log as one contiguous SensorLog; a stretch of NaN/inf rows is refused (the momentum
    balance cannot bridge it)."""
    from estimator.log_reader import read_log

    log = read_log(path, robot)
    if log.n_skipped:
        lines = log.skipped_lines
        raise InputError(f"{path}: {log.n_skipped} rows with a NaN/inf or empty field (lines "
                         f"{lines[0]}–{lines[-1]}): the momentum balance cannot bridge the gap; "
                         f"cut the log there and pass the parts as separate logs")
    if log.n_links != robot.n_links:
        raise InputError(f"{path}: {log.n_links} joints in the log but the robot '{robot.name}' has "
                         f"{robot.n_links} links")
    return log




def run(args) -> int:
    from estimator.robot import PAPER_LEG_TOML
    from estimator.spatial.robot import is_spatial_robot_file
    if args.robot is not None and is_spatial_robot_file(args.robot):   # a URDF robot: the 3-D path
        from torquebench.spatial_identify import identify as identify_3d
        return identify_3d(args)
    robot_path = args.robot or PAPER_LEG_TOML
    from userio.outputs import Outputs

    plan = Outputs(force=args.force)
    for i, log_path in enumerate(args.logs):
        plan.input(f"LOG {i + 1}", log_path, log=True)
    plan.input("--robot", robot_path)
    plan.file("--out", args.out)
    with plan.active():                             # checked before the fit; every write obeys it
        return _identify(args, robot_path)


def _identify(args, robot_path) -> int:
    import datetime
    import sys

    import numpy as np

    from estimator import identification as ident
    from estimator.inertial import robot_toml
    from estimator.robot import load_robot
    from estimator.timing import describe as describe_timing
    from torquebench.io import print_json
    from userio.files import write_text_atomic

    robot = load_robot(robot_path)
    prior, prior_source = fit_prior(args.prior, robot, robot_path)
    eqs, logs_info = [], []
    for path in args.logs:
        log = _read(args, path, robot)
        noise = _noise(args, path, robot.n_links)
        timing = log.timing
        if args.timing is not None:
            from estimator.timing import uniform

            timing = uniform(args.timing, robot.n_links, "--timing")
        eqs.append(ident.window_equations(robot, log.t, log.q, log.dq, log.tau_meas, noise, timing,
                                          args.window, source=str(path)))
        logs_info.append({"path": str(path), "sha256": sha256_of(path), "samples": int(len(log.t)),
                          "noise": noise.describe(),
                          "timing": describe_timing(timing)})
    result = ident.identify(robot, eqs, robot.parameter_covariance(prior))
    for info in logs_info:
        info["excluded_s"] = [[a, b] for a, b in result.excluded.get(info["path"], [])]
    identified = robot.with_parameters(result.theta)
    from dataclasses import replace

    identified = replace(identified, model_uncertainty=None, identification=None,
                         name=f"{robot.name}_identified")
    stats = dict(result.statistics)
    stats["prior"] = prior.describe() + f" ({prior_source})"
    stats["window_s"] = args.window
    table = {"method": "maximum a posteriori fit of the windowed momentum balance (estimator/"
                       "identification.py), prior at the nominal file's values",
             "created_utc": datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ"),
             "command": " ".join(["torquebench", "identify", *sys.argv[2:]]),
             "source_robot": str(robot_path), "source_robot_sha256": sha256_of(Path(robot_path)),
             "parameter_names": list(result.names), "parameters": identified.parameters(),
             "nominal_parameters": result.nominal, "unexcited": result.unexcited,
             "covariance": result.covariance, "statistics": stats, "logs": logs_info}
    header = (f"# {identified.name}: {robot.name} identified by `torquebench identify` from "
              f"{len(args.logs)} log(s); read by estimate, propagate and scenes like any robot file.\n"
              "# The [identification] table states where the values come from and how sure they are.")
    write_text_atomic(args.out, robot_toml(identified, table, header))
    load_robot(args.out)                            # what we wrote reads back (and validates)
    sd = np.sqrt(np.diag(result.covariance))
    rows = [{"name": nm, "nominal": float(a), "identified": float(b), "sigma": float(s),
             "z_from_nominal": float((b - a) / s) if s > 0 else None, "unexcited": nm in result.unexcited}
            for nm, a, b, s in zip(result.names, result.nominal, result.theta, sd)]
    warnings = []
    if result.unexcited:
        warnings.append(f"the logs excite {stats['excited_directions']} of {stats['parameters']} "
                        f"parameter directions: {', '.join(result.unexcited)} not determined by "
                        f"them, kept near their nominal values within the prior "
                        f"({prior.describe()}); more or other motion may identify them "
                        f"(scenes/identification_excitation.toml; base motion for the base and "
                        f"the masses apart)")
    for info in logs_info:
        if info["excluded_s"]:
            spans = ", ".join(f"{a:.3f}–{b:.3f} s" for a, b in info["excluded_s"])
            warnings.append(f"{info['path']}: excluded {spans} (contact or unmodelled force)")
    if result.active_constraints:
        warnings.append("the unconstrained fit was not physically consistent; the consistent fit "
                        f"sits on {len(result.active_constraints)} constraint(s)")
    if args.json:
        print_json({"out": str(args.out), "robot": str(robot_path), "parameters": rows,
                    "statistics": stats, "logs": logs_info, "unexcited": result.unexcited,
                    "warnings": warnings})
        return 0
    print(f"{robot.name}: identified from {len(args.logs)} log(s), {stats['windows_used']} of "
          f"{stats['windows']} windows of {args.window * 1e3:g} ms; wrote {args.out}")
    print(f"  {'parameter':16s} {'nominal':>12s} {'identified':>12s} {'1σ':>10s}")
    for r in rows:
        flag = "  (unexcited: prior)" if r["unexcited"] else ""
        print(f"  {r['name']:16s} {r['nominal']:12.6g} {r['identified']:12.6g} {r['sigma']:10.3g}{flag}")
    rb = ", ".join(f"{v:.3g}" for v in stats["residual_rms_before"])
    ra = ", ".join(f"{v:.3g}" for v in stats["residual_rms_after"])
    print(f"  residual RMS per row (N, N, N·m, …): before [{rb}], after [{ra}]; whitened "
          f"{stats['whitened_rms_before']:.3g} → {stats['whitened_rms_after']:.3g} (noise alone: 1)")
    print(f"  condition number {stats['condition_number_excited']:.3g} over the "
          f"{stats['excited_directions']} excited directions; χ²/dof {stats['chi2_per_dof']:.3g}")
    for w in warnings:
        print(f"  warning: {w}")
    return 0
