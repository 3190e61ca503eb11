"""The commands' URDF path: ``estimate --robot leg.urdf|leg.toml``, ``simulate`` of a 3-D scene,
``propagate --robot leg.toml``. Each command dispatches here on the robot file's kind
(estimator.spatial.robot.is_spatial_robot_file); the planar commands never import this module's
dependencies (pinocchio, trimesh, pyvista)."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from userio.errors import InputError
from torquebench.options import floats as _floats


PLANAR_ONLY = (("method", "dynamic", "--method paper"), ("stance_foot", False, "--stance-foot"),
               ("detector", "chi2", "--detector cusum"), ("quiet_window", None, "--quiet-window"),
               ("debounce", 0, "--debounce"), ("velocity_sigma", None, "--velocity-sigma"),
               ("encoder_counts", None, "--encoder-counts"))


def estimate(args) -> int:
    """``torquebench estimate LOG --robot leg.urdf``: the 3-D estimator (estimator.spatial)."""
    from estimator.noise import parse_rate
    from estimator.spatial.logs import SpatialLogReader, make_noise, read_noise
    from estimator.spatial.model import UrdfModel
    from estimator.spatial.pipeline import SpatialStream
    from estimator.spatial.robot import load_spatial_robot
    from torquebench.io import print_json

    start = time.perf_counter()
    for attr, default, flag in PLANAR_ONLY:
        if getattr(args, attr, default) != default:
            raise InputError(f"{flag}: not available for a URDF robot ({args.robot}); the 3-D "
                             f"estimator runs the chi-square detector and surface localization")
    robot = load_spatial_robot(args.robot)
    model = UrdfModel(robot)
    n_sensed = int(sum(robot.sensed))
    noise = None
    if args.torque_sigma is not None or args.ft_sigma is not None:
        noise = make_noise(_floats(args.torque_sigma or "0.005", "--torque-sigma"),
                           _floats(args.ft_sigma or "0.1,0.01", "--ft-sigma"), n_sensed,
                           source="--torque-sigma/--ft-sigma")
    else:
        noise = read_noise(args.log, robot)
    rate = parse_rate(args.false_alarm_rate, "--false-alarm-rate")
    from estimator.model_error import resolve
    from torquebench.options import model_uncertainty_option

    given = model_uncertainty_option(getattr(args, "model_uncertainty", None))
    if args.threshold is not None:
        if given not in (None, False):
            raise InputError("--model-uncertainty: enters the chi-square detector; not with --threshold")
        model_cov, model_source = None, "none (--threshold)"
    else:                      # the file's identification or [model_uncertainty], unless an option
        model_cov, model_source = resolve(model, given)
    reader = SpatialLogReader(args.log, robot, model, chunk_samples=args.chunk_samples)
    timing = reader.timing
    if args.timing is not None:
        from estimator.timing import parse

        timing = [parse(args.timing, "--timing")] * model.n_v
    chunks = iter(reader)
    first = next(chunks)
    from estimator.plausibility import check_head_model

    found = check_head_model(model, first, noise, where=str(args.log))   # units, signs: refused
    stream = SpatialStream(model, reader.period_s, gain_per_s=args.gain, noise=noise, timing=timing,
                           false_alarm_rate=rate, threshold=args.threshold,
                           weighting=getattr(args, "weighting", "whitened"),
                           model_cov=model_cov, model_source=model_source)
    stream.feed(first)
    for c in chunks:
        stream.feed(c)
    est = stream.finish()
    if args.out is not None:
        from userio.files import atomic_write

        frame = est.frame
        if Path(args.out).suffix.lower() == ".parquet":
            atomic_write(args.out, lambda tmp: frame.to_parquet(tmp, index=False))
        else:
            atomic_write(args.out, lambda tmp: frame.to_csv(tmp, index=False, float_format="%.9g"))
    if getattr(args, "png", None) is not None:
        pictures = _contact_pictures(model, args, est)
    summary = {"log": str(args.log), "robot": robot.name, "urdf": str(robot.urdf_path),
               "gain_per_s": args.gain, "skipped_samples": reader.n_skipped,
               "timing": "declared" if reader.timing is not None else "instant",
               **est.summary(), "run_time_s": time.perf_counter() - start}
    if args.out is not None:
        summary["out"] = str(args.out)
    if getattr(args, "png", None) is not None:
        summary["png"] = pictures
    from estimator.plausibility import attach_warnings

    attach_warnings(summary, found)
    if args.json:
        print_json(summary)
        return 0
    print(f"{args.log}: {summary['samples']} samples, robot {robot.name} (URDF), "
          f"{summary['contact_samples']} in contact, {summary['run_time_s']:.2f} s")
    print(f"  detector: {summary['detector']}, {summary['false_alarm_rate_per_s'] * 3600:.3g} false "
          f"alarms/h on {summary['chi2_dof']} rows; residual noise from {summary['residual_noise_source']}")
    for iv in summary["intervals"]:
        print(f"  contact {iv['t_start_s']:.4f}-{iv['t_end_s']:.4f} s: link {iv['link'] or '—'} "
              f"({100 * iv['located_fraction']:.0f} % located), p = ({iv['px_m']:.4f}, "
              f"{iv['py_m']:.4f}, {iv['pz_m']:.4f}) m, F = ({iv['Fx_N']:.3f}, {iv['Fy_N']:.3f}, "
              f"{iv['Fz_N']:.3f}) N")
    if args.out is not None:
        print(f"wrote {args.out}")
    return 0


def _contact_pictures(model, args, est) -> list[str]:
    """One picture per contact interval at its middle sample (estimator.spatial.render)."""
    import pandas as pd

    from estimator.spatial.logs import read_spatial_log
    from estimator.spatial.predict import SurfaceMap, solid_mesh
    from estimator.spatial.geometry import body_surfaces
    from estimator.spatial.render import contact_picture

    log = read_spatial_log(args.log, model.robot, model)
    truth_file = Path(args.log).with_name(Path(args.log).stem + ".truth.csv")
    truth = pd.read_csv(truth_file, keep_default_na=False, na_values=["nan", ""]) if truth_file.exists() else None
    maps = []
    for s in body_surfaces(model.robot, model.tree):
        for link, shape in s.solids:
            m = solid_mesh(shape, 24)
            maps.append(SurfaceMap(link, s.body, m.vertices, m.faces, np.zeros(len(m.vertices)), None))
    out = []
    f = est.frame
    for i, iv in enumerate(est.intervals, start=1):
        k = int(np.searchsorted(f.t.to_numpy(), 0.5 * (iv["t_start_s"] + iv["t_end_s"])))
        row = f.iloc[k]
        tp = tf = None
        if truth is not None and str(truth.link.iloc[k] or "") != "":
            tp = truth[["px", "py", "pz"]].to_numpy()[k]
            tf = truth[["Fx", "Fy", "Fz"]].to_numpy()[k]
        path = Path(args.png) if i == 1 else Path(args.png).with_name(f"{Path(args.png).stem}_{i}.png")
        from userio.outputs import current

        if i > 1 and current() is not None:
            current().file("--png", path)            # checked against the inputs as it is written
        contact_picture(model, log.q[k], maps, row[["px", "py", "pz"]].to_numpy(float),
                        row[["Fx", "Fy", "Fz"]].to_numpy(float), tp, tf, path)
        out.append(str(path))
    return out


def simulate(args) -> int:
    """``torquebench simulate SCENE.toml`` for a scene whose robot is a URDF."""
    from estimator.noise import noise_side_file
    from estimator.spatial.logs import noise_text, write_spatial_log
    from estimator.spatial.scene import load_spatial_scene
    from estimator.spatial.sim import simulate as run_sim
    from estimator.timing import side_file
    from torquebench.io import print_json
    from userio.files import atomic_write, remove, write_text_atomic

    scene = load_spatial_scene(args.scene)
    spec = scene.spec
    if args.duration is not None:
        spec.duration_s = float(args.duration)
    if args.seed is not None:
        spec.seed = int(args.seed)
    start = time.perf_counter()
    log, truth, noise = run_sim(scene.robot, spec)
    out = Path(args.out)
    tpath = out.with_name(out.stem + ".truth" + (out.suffix or ".csv"))
    write_spatial_log(log, scene.robot, out)
    atomic_write(tpath, lambda tmp: truth.to_csv(tmp, index=False, float_format="%.17g"))
    write_text_atomic(side_file(out), '# every channel read at the sample time (estimator.spatial.sim)\n'
                                      '[timing]\ndefault = "instant"\n')
    nfile = noise_side_file(out)
    if noise is not None:
        write_text_atomic(nfile, noise_text(noise))
    else:
        remove(nfile)             # an old noise file of another log (the plan's rules: never the user's)
    summary = {"scene": scene.name, "robot": scene.robot.name, "log": str(out), "truth": str(tpath),
               "samples": len(log.t), "contact_samples": int((truth["link"] != "").sum()),
               "run_time_s": time.perf_counter() - start}
    if args.json:
        print_json(summary)
    else:
        print(f"{scene.name}: {summary['samples']} samples, {summary['contact_samples']} in contact → "
              f"{out} (+ {tpath.name}); {summary['run_time_s']:.2f} s")
    return 0


def _identifiability(model) -> list:
    from estimator.spatial.geometry import body_surfaces
    from estimator.spatial.localize import identifiability

    return identifiability(model, body_surfaces(model.robot, model.tree))


def propagate(args) -> int:
    """``torquebench propagate --robot leg.toml``: the 3-D error map (estimator.spatial.predict)
    at a posture, for a force of the given magnitude pushing into every surface point."""
    from estimator.spatial.logs import make_noise
    from estimator.spatial.model import UrdfModel
    from estimator.spatial.predict import error_map, summarize
    from estimator.spatial.robot import load_spatial_robot
    from torquebench.io import print_json

    robot = load_spatial_robot(args.robot)
    model = UrdfModel(robot)
    ft = _floats(args.ft_noise, "--ft-noise")
    if len(ft) == 3:                    # the planar form Fx, Fz, My: force σ, moment σ
        ft = [ft[0], ft[2]]
    tau = args.torque_noise_Nm if args.torque_noise_Nm is not None else 0.005
    noise = make_noise(tau, ft, int(sum(robot.sensed)), source="--torque-noise-Nm/--ft-noise")
    magnitude = _floats(args.force, "--force")[0]
    if not magnitude > 0:
        raise InputError(f"--force: the magnitude must be > 0 N, got {magnitude:g}")
    q = robot.rest_q()
    if getattr(args, "posture", None):
        post = _floats(args.posture, "--posture")
        if len(post) != robot.n_joints:
            raise InputError(f"--posture: expected {robot.n_joints} joint values "
                             f"({', '.join(robot.joint_names)}), got {len(post)}")
        q[7:] = post
    maps = error_map(model, q, noise, magnitude, args.gain, 1.0 / args.rate,
                     resolution=max(8, 4 * args.grid))
    results = {"robot": robot.name, "urdf": str(robot.urdf_path), "posture_rad": q[7:].tolist(),
               "force_N": magnitude, "torque_noise_std_Nm": float(tau), "ft_noise": noise.ft_sigma.tolist(),
               "links": summarize(maps), "identifiability": _identifiability(model),
               "method": "first-order propagation of the residual's no-contact covariance through "
                         "the surface localizer, force pushing straight into each surface point"}
    if args.png:
        from estimator.spatial.render import error_picture

        error_picture(model, q, maps, args.png, f"RMS contact-position error, {magnitude:g} N pushes")
        results["png"] = str(args.png)
    if args.json:
        print_json(results)
        return 0
    print(f"{robot.name}: τ σ {tau:g} N·m, FT σ {noise.ft_sigma.tolist()}, |F| = {magnitude:g} N, "
          f"posture {np.round(q[7:], 3).tolist()} rad")
    for link, s in results["links"].items():
        med, mx = s["position_rms_median_m"], s["position_rms_max_m"]
        print(f"  {link:12s} median {med * 1e3 if med is not None else float('nan'):7.2f} mm, "
              f"max {mx * 1e3 if mx is not None else float('nan'):7.2f} mm, refused "
              f"{100 * s['refused_fraction']:.0f} % of {s['points']} surface points")
    for d in results["identifiability"]:
        if d["confused_with"]:
            print(f"  {d['link']}: told apart from {', '.join(d['confused_with'])} only by where the line "
                  f"of action meets their surfaces (no torque sensor between them)")
    return 0
