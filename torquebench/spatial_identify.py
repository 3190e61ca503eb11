"""``torquebench identify LOG.csv … --robot leg.toml|leg.urdf --out IDENTIFIED.toml``: the URDF
robot's path (dispatched from torquebench.commands.identify on the robot file's kind). The same fit
(estimator.identification) on the UrdfModel's regressor; writes IDENTIFIED.urdf (the identified
inertias, estimator.spatial.write) and IDENTIFIED.toml (the declaration with its [identification]).

Rows: the six base rows and the sensed joints (an unsensed joint's row has no measured torque: not
an equation). Noise of the base rows: the FT sensor's σ (sensor frame) mapped to the base rows at
the log's first posture, diagonal (``ft_map``); the joint rows: the torque sensors' σ."""

from __future__ import annotations

import datetime
import sys
from pathlib import Path

import numpy as np

from userio.errors import InputError


class _RowNoise:
    """What estimator.identification.window_equations reads of a noise model, per observer row."""

    def __init__(self, sigma_rows, velocity_sigma):
        self.ft_sigma = np.asarray(sigma_rows, float)     # every row (the fit's ``_force_sigma``)
        self.torque_sigma_Nm = np.zeros(0)
        self.velocity_sigma_rad_per_s = float(velocity_sigma)


def _row_sigma(model, noise, q0) -> np.ndarray:
    F = model.ft_map(q0[None])[0]
    base = np.sqrt(np.einsum("ij,j,ij->i", F, np.asarray(noise.ft_sigma, float) ** 2, F))
    tau = np.ones(len(model.joint_names))                 # unsensed rows: dropped later
    tau[np.flatnonzero(model.sensed_joints)] = noise.torque_sigma_Nm
    return np.r_[base, tau]


def _keep_rows(e, rows):
    e.A, e.b = e.A[:, rows], e.b[:, rows]
    e.C = e.C[:, rows][:, :, rows]
    return e


def identify(args) -> int:
    from estimator.spatial.robot import load_spatial_robot

    robot_path = Path(args.robot)
    out = Path(args.out)
    if out.suffix.lower() != ".toml":
        raise InputError(f"--out {out}: a URDF robot is written as IDENTIFIED.toml beside "
                         f"IDENTIFIED.urdf; give a .toml name")
    out_urdf = out.with_suffix(".urdf")
    robot = load_spatial_robot(robot_path)
    from userio.outputs import Outputs

    plan = Outputs(force=args.force)
    for i, log_path in enumerate(args.logs):
        plan.input(f"LOG {i + 1}", log_path, log=True)
    plan.input("--robot", robot_path)
    plan.input("the robot's URDF", robot.urdf_path)
    plan.file("--out", out)
    plan.file("--out (its URDF)", out_urdf)
    with plan.active():                             # checked before the fit; every write obeys it
        return _identify(args, robot_path, robot, out, out_urdf)


def _identify(args, robot_path, robot, out, out_urdf) -> int:
    from estimator import identification as ident
    from estimator.spatial.logs import make_noise, read_noise, read_spatial_log, read_timing
    from estimator.spatial.model import UrdfModel
    from estimator.spatial.noise import default_noise
    from estimator.spatial.observer import used_rows
    from estimator.spatial.robot import load_spatial_robot
    from estimator.spatial.write import declaration_toml, urdf_with_parameters
    from estimator.timing import describe as describe_timing
    from torquebench.options import fit_prior
    from userio.outputs import sha256_of
    from torquebench.io import print_json
    from userio.files import read_toml, write_text_atomic

    model = UrdfModel(robot)
    prior, prior_source = fit_prior(args.prior, robot, robot_path)
    n_sensed = int(sum(robot.sensed))
    rows = used_rows(model)
    eqs, logs_info = [], []
    for path in args.logs:
        log = read_spatial_log(path, robot, model)
        if log.n_skipped:
            raise InputError(f"{path}: {log.n_skipped} rows with a NaN/inf or empty field: the momentum "
                             f"balance cannot bridge the gap; cut the log there and pass the parts "
                             f"as separate logs")
        if args.torque_sigma is not None or args.ft_sigma is not None or args.velocity_sigma is not None:
            from torquebench.options import floats as _floats

            noise = make_noise(_floats(args.torque_sigma or "0.005", "--torque-sigma"),
                               _floats(args.ft_sigma or "0.1,0.01", "--ft-sigma"), n_sensed,
                               velocity_sigma=float(args.velocity_sigma or 0.0),
                               source="--torque-sigma/--ft-sigma/--velocity-sigma")
        else:
            noise = read_noise(path, robot) or default_noise(model)
        timing = read_timing(path, robot)
        if args.timing is not None:
            from estimator.timing import parse

            timing = [parse(args.timing, "--timing")] * model.n_v
        rn = _RowNoise(_row_sigma(model, noise, log.q[0]), noise.velocity_sigma_rad_per_s)
        e = ident.window_equations(model, log.t, log.q, log.v, log.tau_meas(model), rn, timing,
                                   args.window, source=str(path))
        eqs.append(_keep_rows(e, rows))
        logs_info.append({"path": str(path), "sha256": sha256_of(Path(path)), "samples": int(len(log.t)),
                          "noise": noise.describe(), "timing": describe_timing(timing)})
    result = ident.identify(model, eqs, model.parameter_covariance(prior))
    for info in logs_info:
        info["excluded_s"] = [[a, b] for a, b in result.excluded.get(info["path"], [])]
    stats = dict(result.statistics)
    stats["prior"] = prior.describe() + f" ({prior_source})"
    stats["window_s"] = args.window
    name = f"{robot.name}_identified"
    table = {"method": "maximum a posteriori fit of the windowed momentum balance (estimator/"
                       "identification.py), prior at the nominal file's values",
             "created_utc": datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ"),
             "command": " ".join(["torquebench", "identify", *sys.argv[2:]]),
             "source_robot": str(robot_path), "source_robot_sha256": sha256_of(robot_path),
             "parameter_names": list(result.names), "parameters": result.theta,
             "nominal_parameters": result.nominal, "unexcited": result.unexcited,
             "covariance": result.covariance, "statistics": stats, "logs": logs_info}
    declaration = read_toml(robot_path) if robot_path.suffix.lower() == ".toml" else {}
    header = (f"# {name}: {robot.name} identified by `torquebench identify` from {len(args.logs)} "
              f"log(s); the inertias are in {out_urdf.name}.\n# The [identification] table states "
              f"where the values come from and how sure they are.")
    write_text_atomic(out_urdf, urdf_with_parameters(model, result.theta))
    write_text_atomic(out, declaration_toml(declaration, out_urdf.name, name, robot_path.parent,
                                            table, header))
    load_spatial_robot(out)                         # what we wrote reads back (and validates)
    sd = np.sqrt(np.diag(result.covariance))
    table_rows = [{"name": nm, "nominal": float(a), "identified": float(b), "sigma": float(s),
                   "unexcited": nm in result.unexcited}
                  for nm, a, b, s in zip(result.names, result.nominal, result.theta, sd)]
    warnings = []
    if result.unexcited:
        warnings.append(f"the logs excite {stats['excited_directions']} of {stats['parameters']} "
                        f"parameter directions; {len(result.unexcited)} parameters kept near their "
                        f"nominal values within the prior ({prior.describe()})")
    if result.active_constraints:
        warnings.append("the unconstrained fit was not physically consistent; the consistent fit "
                        f"sits on {len(result.active_constraints)} constraint(s)")
    if args.json:
        print_json({"out": str(out), "urdf": str(out_urdf), "robot": str(robot_path),
                    "parameters": table_rows, "statistics": stats, "logs": logs_info,
                    "unexcited": result.unexcited, "warnings": warnings})
        return 0
    print(f"{robot.name} (URDF): identified from {len(args.logs)} log(s), {stats['windows_used']} of "
          f"{stats['windows']} windows of {args.window * 1e3:g} ms; wrote {out} and {out_urdf}")
    for r in table_rows:
        flag = "  (unexcited: prior)" if r["unexcited"] else ""
        print(f"  {r['name']:16s} {r['nominal']:12.6g} {r['identified']:12.6g} {r['sigma']:10.3g}{flag}")
    print(f"  χ²/dof {stats['chi2_per_dof']:.3g}; condition number {stats['condition_number_excited']:.3g} "
          f"over the {stats['excited_directions']} excited directions")
    for w in warnings:
        print(f"  warning: {w}")
    return 0
