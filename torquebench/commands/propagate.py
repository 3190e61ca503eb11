"""`torquebench propagate`: what contact-localization error will this sensor design give on the leg?

A view over the stage graph (torquebench.pipeline: sensor_chain → error_map): the options make a
scene. A sensor configuration (bridge/ADC, ``sensors/paper_sensor.toml``) and a
strain per N·m (given, or from the bridge default) give the joint-torque noise σ_τ; a calibration
file gives the slope uncertainty (a systematic gain error); the FT sensor noise is Table II's.
``estimator.uncertainty`` then propagates them through the localizer over a grid of postures
(the paper's sweep: q ∈ [0, π]²), by Monte Carlo and to first order. Beside it, over the same
postures × ``--directions`` force directions, the Cramér–Rao bound of the contact point (per
sample and over a ``--hold``) and our estimator's predicted error (``estimator.bound_maps``):
where a contact can be localized and where not (the bound diverges as the force turns along the
link, where the estimator refuses); in the JSON under ``bounds`` and in the ``--png`` picture.
"""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np

from userio.errors import InputError

HELP = "propagate sensor noise and calibration uncertainty into contact-localization error"
EXAMPLES = """\
torquebench propagate --grid 4 --draws 200
torquebench propagate --calibration calibration/data/paper_link1_cal.json --grid 6 --png out/position_error.png --json
torquebench propagate --robot robots/quadruped_leg.toml --posture 0.2,0.6,-1.2 --force 5 --png out/leg_error_map.png
"""


def _floats(text: str, count: int, name: str) -> list[float]:
    try:
        values = [float(v) for v in text.split(",")]
    except ValueError:
        raise InputError(f"{name}: expected {count} comma-separated numbers, got {text!r}") from None
    if len(values) != count or not all(math.isfinite(v) for v in values):
        raise InputError(f"{name}: expected {count} finite comma-separated numbers, got {text!r}")
    return values


def _finite_args(args) -> None:
    """Numbers from the command line are finite and physically sized."""
    from userio.errors import finite

    if args.strain_per_Nm is not None:
        finite(args.strain_per_Nm, "--strain-per-Nm", positive=True, hi=1.0)
    if args.torque_noise_Nm is not None:
        finite(args.torque_noise_Nm, "--torque-noise-Nm", lo=0.0, hi=1e6)
    if args.gain_error is not None:
        finite(args.gain_error, "--gain-error", lo=0.0, hi=1.0)
    finite(args.hold, "--hold", positive=True, hi=3600.0)
    if not 1 <= args.directions <= 720:
        raise InputError(f"--directions: expected 1…720, got {args.directions}")


def add_arguments(parser) -> None:
    parser.add_argument("--robot", type=Path, help="robot TOML (default: robots/paper_leg.toml), or a URDF robot "
                        "(a .urdf or a declaration naming one): the 3-D error map over its link surfaces")
    parser.add_argument("--posture", default=None, metavar="RAD,RAD,...",
                        help="URDF robots: joint angles of the 3-D error map, rad (default: all 0)")
    parser.add_argument("--sensor", type=Path, help="sensor TOML (default: sensors/paper_sensor.toml)")
    parser.add_argument("--strain-per-Nm", type=float, dest="strain_per_Nm",
                        help="gauge strain per N·m of joint torque, 1/(N·m) (default: the sensor file's, or the paper's)")
    parser.add_argument("--torque-noise-Nm", type=float, dest="torque_noise_Nm",
                        help="joint-torque noise std per sample in N·m (default: from the sensor's bridge and ADC)")
    parser.add_argument("--calibration", type=Path, help="calibration JSON from `calibrate`: its reading noise through its slope gives σ_τ "
                             "(unless --torque-noise-Nm), checked against the sensor chain's; its slope "
                             "uncertainty becomes a gain error")
    parser.add_argument("--gain-error", type=float, default=None,
                        help="relative calibration gain error std, dimensionless (default: from --calibration, else 0)")
    parser.add_argument("--ft-noise", default="0.1,0.1,0.01", help="σ of the base wrench Fx [N], Fz [N], My [N·m] (default: %(default)s, the paper's Table II)")
    parser.add_argument("--contact", default="2,0.8", help="LINK,ALPHA of the contact: link number and fraction along it (default: %(default)s, Table III test 2)")
    parser.add_argument("--force", default=f"7,{-math.pi / 3}", help="MAGNITUDE_N,DIRECTION_RAD of the contact force, direction from +x counter-clockwise (default: 7 N at −π/3)")
    parser.add_argument("--grid", type=int, default=10, help="postures per joint over [0, π] rad (default: %(default)s)")
    parser.add_argument("--rate", type=float, default=1000.0, help="sample rate in Hz (default: %(default)s)")
    parser.add_argument("--gain", type=float, default=100.0, help="observer gain K in 1/s (default: %(default)s)")
    parser.add_argument("--draws", type=int, default=500, help="Monte Carlo draws per posture, at least 2 (default: %(default)s)")
    parser.add_argument("--max-localizations", type=float, default=2e7, metavar="N",
                        help="refuse, before any work, a run of more than N localizations "
                             "(postures × (draws × 2 methods + directions × min(draws, 200))) "
                             "(default: %(default)g)")
    parser.add_argument("--seed", type=int, default=0, help="Monte Carlo seed (default: %(default)s)")
    parser.add_argument("--model-uncertainty", default=None, metavar="REL|none",
                        help="relative 1σ of the robot's inertial data (masses, inertias, and "
                             "centres of mass as a fraction of each link's length), a systematic "
                             "error drawn once per robot; 'none' leaves it out (default: the robot "
                             "file's [identification] covariance, else its [model_uncertainty], "
                             "else none)")
    parser.add_argument("--hold", type=float, default=0.5, metavar="S",
                        help="contact hold time of the episode bound, s (default: %(default)s)")
    parser.add_argument("--directions", type=int, default=24, metavar="N",
                        help="force directions of the bound maps, over the full circle from the "
                             "--force direction (default: %(default)s)")
    parser.add_argument("--png", type=Path, help="write a heat map of the position error (m) over the posture grid; directory created, an existing file is never replaced")


def provenance_from_args(args) -> dict:
    """Where σ_τ and the gain error come from, as the command line says."""
    provenance = {}
    if args.torque_noise_Nm is not None:
        provenance["torque_noise_source"] = "--torque-noise-Nm"
    elif args.sensor is not None:
        provenance["torque_noise_source"] = f"bridge chain of {args.sensor}"
    else:
        provenance["torque_noise_source"] = "bridge chain of the paper's sensor"
    return provenance


def _model_uncertainty(text):
    """--model-uncertainty REL | none → REL, 0.0 (none) or None (the robot file's)."""
    from torquebench.options import model_uncertainty_option

    mu = model_uncertainty_option(text)
    return None if mu is None else (0.0 if mu is False else mu.relative)


def scene_from_args(args, robot, link, alpha, magnitude, direction):
    """The prediction scene of the command line: robot, [sensor] file, strain per N·m and
    calibration file as the chain's inputs, and the posture-grid settings."""
    from torquebench.scenes import ChainSpec, PredictionSpec, prediction_scene

    from userio.files import check_input

    if args.sensor is not None:           # a regular file of a sane size: not a directory or a device
        check_input(args.sensor, "--sensor", what="sensor TOML file")
    if args.calibration is not None and os.path.lexists(args.calibration):   # read only when needed
        check_input(args.calibration, "--calibration", what="calibration JSON file")
    chain = ChainSpec(strain_per_Nm=args.strain_per_Nm, sensor_file=args.sensor,
                      calibration_file=args.calibration)
    pred = PredictionSpec(link=link, alpha=alpha, magnitude_N=magnitude, direction_rad=direction,
                          grid=args.grid, draws=args.draws, seed=args.seed, sample_rate_Hz=args.rate,
                          gain_per_s=args.gain, ft_noise=tuple(_floats(args.ft_noise, 3, "--ft-noise")),
                          torque_noise_Nm=args.torque_noise_Nm, gain_error=args.gain_error,
                          model_uncertainty=_model_uncertainty(args.model_uncertainty),
                          hold_s=args.hold, directions=args.directions)
    return prediction_scene(robot, chain, pred)


def run(args) -> int:
    from userio.errors import finite, seed

    seed(args.seed)                              # negative seeds → exit 2
    _finite_args(args)
    from estimator.spatial.robot import is_spatial_robot_file
    if args.robot is not None and is_spatial_robot_file(args.robot):   # a URDF robot: the 3-D map
        from estimator.spatial.robot import load_spatial_robot
        from torquebench.spatial_cli import propagate as propagate_3d
        from userio.outputs import Outputs

        plan = Outputs(force_flag=None)          # --force is the contact force here: never replace
        plan.input("--robot", args.robot)
        plan.input("the robot's URDF", load_spatial_robot(args.robot).urdf_path)
        plan.file("--png", args.png)
        with plan.active():                      # checked now; the picture obeys it
            return propagate_3d(args)
    from estimator.robot import load_robot, paper_leg
    from torquebench import pipeline as P
    from torquebench.cache import Cache
    from torquebench.io import print_json

    if getattr(args, "posture", None) is not None:
        raise InputError("--posture: for URDF robots (--robot LEG.toml naming a URDF); a planar robot's "
                         "map covers a grid of postures over [0, π] per joint (--grid)")
    robot = load_robot(args.robot) if args.robot else paper_leg()
    parts = str(args.contact).split(",")
    try:
        if len(parts) != 2:
            raise ValueError
        link, alpha = int(parts[0]), float(parts[1])
    except ValueError:
        raise InputError(f"--contact: expected exactly LINK,ALPHA (two values, e.g. 2,0.8), got "
                         f"{args.contact!r}") from None
    if not (1 <= link <= robot.n_links and 0.0 <= alpha <= 1.0):
        raise InputError(f"--contact: link must be 1…{robot.n_links} and α in [0, 1], got {args.contact!r}")
    magnitude, direction = _floats(args.force, 2, "--force")
    if args.grid < 1 or args.draws < 2:
        raise InputError("--grid must be ≥ 1 and --draws ≥ 2")
    if magnitude < 0:
        raise InputError(f"--force: the magnitude must be ≥ 0 N (the direction carries the sign), got {magnitude:g}")
    work = float(args.grid) ** robot.n_links * (args.draws * 2 + args.directions * min(args.draws, 200))
    if work > finite(args.max_localizations, "--max-localizations", positive=True):
        raise InputError(f"--grid/--draws/--directions: {args.grid}^{robot.n_links} postures × ({args.draws} "
                         f"draws × 2 methods + {args.directions} directions × {min(args.draws, 200)} "
                         f"draws) = {work:.3g} localizations, above --max-localizations "
                         f"{args.max_localizations:.3g}; reduce them or raise the limit")
    if args.png and robot.n_links != 2:
        raise InputError("--png: the heat map is drawn for two-link robots only")
    from userio.outputs import Outputs

    plan = Outputs(force_flag=None)              # --force is the contact force here: never replace
    for label, p in (("--robot", args.robot), ("--sensor", args.sensor), ("--calibration", args.calibration)):
        plan.input(label, p)
    plan.file("--png", args.png)
    scene = scene_from_args(args, robot, link, alpha, magnitude, direction)
    with plan.active():                          # checked now; the write obeys it
        return _propagate(args, scene, robot, link, alpha, magnitude, direction)


def _propagate(args, scene, robot, link, alpha, magnitude, direction) -> int:
    from torquebench import pipeline as P
    from torquebench.cache import Cache
    from torquebench.io import print_json

    arts, _ = P.execute(scene, ["error_map"], Cache())       # sensor_chain → error_map (stage graph)
    em = arts["error_map"]
    noise, axes, maps = em["noise"], em["axes"], em["maps"]
    provenance = provenance_from_args(args)
    if "chain" in arts:
        provenance["strain_per_Nm"] = arts["chain"].strain_per_Nm
    if args.torque_noise_Nm is None and args.calibration is not None:
        provenance["torque_noise_source"] = em["torque_noise_source"]
    if args.gain_error is None and args.calibration is not None:
        provenance["gain_error_source"] = str(args.calibration)

    results = {"torque_noise_std_Nm": float(noise.torque_std_Nm[0]),
               "gain_error_rel_std": float(noise.torque_gain_rel_std[0]),
               "ft_noise": noise.wrench_std.tolist(), "postures": em["postures"],
               "contact": {"link": link, "alpha": alpha, "force_N": magnitude, "direction_rad": direction},
               "model_uncertainty_source": em["model_uncertainty_source"],
               **provenance, "methods": dict(em["methods"]),
               "bounds": bounds_json(em.get("bounds", {}), link, alpha, magnitude),
               "warnings": list(em.get("warnings", []))}
    if args.png:
        _heat_map(args.png, maps, axes, em.get("bounds", {}))
        results["png"] = str(args.png)
    if args.json:
        print_json(results)
        return 0
    print(f"σ_τ = {results['torque_noise_std_Nm']:.4g} N·m ({provenance.get('torque_noise_source')}), "
          f"gain error {results['gain_error_rel_std']:.3g}, σ_FT = {results['ft_noise']}")
    print(f"model uncertainty: {results['model_uncertainty_source']}")
    for w in results["warnings"]:
        print(f"WARNING: {w}")
    print(f"contact: link {link}, α = {alpha}, |F| = {magnitude} N at {direction:.3f} rad; "
          f"{results['postures']} postures × {args.draws} draws")
    print(f"{'method':8s} {'median |p| RMS':>15s} {'max |p| RMS':>12s} {'max p95':>9s} "
          f"{'median |F| RMS':>15s} {'flagged':>8s} {'MC/1st-order':>13s}")
    for method, m in results["methods"].items():
        def mm(v, e=None):
            if v is None:
                return "—"
            return f"{v * 1e3:.2f}" + (f"±{e * 1e3:.2f}" if e is not None and np.isfinite(e) else "") + " mm"
        print(f"{method:8s} {mm(m['position_rms_median_m'], m['position_rms_median_m_error_estimate']):>15s} {mm(m['position_rms_max_m']):>12s} "
              f"{mm(m['position_p95_max_m'], m['position_p95_max_m_error_estimate']):>9s} {m['force_rms_median_N'] or float('nan'):>13.3f} N "
              f"{m['flagged_postures']:>8d} {m['monte_carlo_over_first_order_median'] or float('nan'):>13.3f}")
    b = results["bounds"]
    if b.get("per_sample_bound_median_m") is not None:
        print(f"Cramér–Rao bound along the link at this force: median {b['per_sample_bound_median_m'] * 1e3:.3f} mm "
              f"per sample, {b['episode_bound_median_m'] * 1e3:.3f} mm over a {b['hold_s']:g} s hold; our "
              f"estimator {b['estimator_over_bound_median']:.2f}× the per-sample bound (median, p90 "
              f"{b['estimator_over_bound_p90']:.2f}); it answers in {b['localizable_fraction'] * 100:.0f} % "
              f"of {len(b['directions_rad'])} directions × {results['postures']} postures (refused: the force "
              f"within {b['refused_within_deg_of_link']:.1f}° of the link)")
    return 0


def bounds_json(m: dict, link: int, alpha: float, magnitude: float) -> dict:
    """The bound maps as JSON: arrays over postures × directions (NaN → null) and a summary."""
    if "bound_per_sample_m" not in m:
        return {"reason": m.get("reason", "not computed")}
    def arr(a):
        return [[(float(v) if np.isfinite(v) else None) for v in row] for row in np.asarray(a)]
    bp, est, ref = m["bound_per_sample_m"], m["estimator_rms_m"], m["refused_fraction"]
    ratio = est / bp
    ok = np.isfinite(ratio)
    refused = ref > 0.5
    sin = m["sin_angle"]
    return {
        "method": "Cramér–Rao bound of the whitened residual (estimator.bounds), along the link, 1σ; "
                  "the estimator's RMS by Monte Carlo of the per-sample localizer (estimator.bound_maps)",
        "contact": {"link": link, "alpha": alpha, "force_N": magnitude}, "hold_s": m["hold_s"],
        "draws": m["draws"], "directions_rad": [float(v) for v in m["directions_rad"]],
        "per_sample_bound_median_m": float(np.median(bp[:, 0])),
        "episode_bound_median_m": float(np.median(m["bound_episode_m"][:, 0])),
        "estimator_over_bound_median": float(np.median(ratio[ok])) if ok.any() else None,
        "estimator_over_bound_p90": float(np.percentile(ratio[ok], 90)) if ok.any() else None,
        "localizable_fraction": float(np.mean(~refused)),
        "refused_within_deg_of_link": float(np.degrees(np.arcsin(np.clip(sin[refused].max(), 0, 1))))
        if refused.any() else 0.0,
        "per_sample_bound_m": arr(bp), "episode_bound_m": arr(m["bound_episode_m"]),
        "estimator_rms_m": arr(est), "refused_fraction": arr(ref)}


def _heat_map(path: Path, maps: dict, axes, bmaps: dict | None = None) -> None:
    """One picture (two-link robots): the position-error maps over the (q1, q2) grid, one panel
    per method; and the bound maps (estimator.bound_maps): the per-sample Cramér–Rao bound and
    our estimator's RMS at the scene's force (blank: it refuses), the share of force directions
    it answers, and both against the force direction at the median posture."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.colors import LogNorm

    from userio.files import atomic_path

    have_b = bool(bmaps) and "bound_per_sample_m" in bmaps
    rows = 2 if have_b else 1
    fig, axs = plt.subplots(rows, 3 if have_b else len(maps), figsize=(15 if have_b else 5 * len(maps), 4 * rows),
                            constrained_layout=True, squeeze=False)
    shape = (len(axes[0]), len(axes[1]))
    ext = [0, math.pi, 0, math.pi]
    for ax, (method, values) in zip(axs[0], maps.items()):
        im = ax.imshow(values.reshape(shape).T * 1e3, origin="lower", extent=ext, aspect="auto")
        ax.set(title=f"{method}: contact position RMS error", xlabel="q1 [rad]", ylabel="q2 [rad]")
        fig.colorbar(im, ax=ax, label="mm (blank: flagged)")
    if have_b:
        bp, est = bmaps["bound_per_sample_m"], bmaps["estimator_rms_m"]
        ans = 1.0 - np.mean(bmaps["refused_fraction"] > 0.5, axis=1)
        ax = axs[0, 2]
        im = ax.imshow(ans.reshape(shape).T * 100, origin="lower", extent=ext, aspect="auto", vmin=0, vmax=100)
        ax.set(title=f"force directions localized ({bp.shape[1]})", xlabel="q1 [rad]", ylabel="q2 [rad]")
        fig.colorbar(im, ax=ax, label="% of directions")
        lo = np.nanmin(np.where(np.isfinite(bp[:, 0]), bp[:, 0], np.nan)) * 1e3
        hi = np.nanmax(np.where(np.isfinite(bp[:, 0]), bp[:, 0], np.nan)) * 1e3
        norm = LogNorm(vmin=max(lo, 1e-6), vmax=max(hi, lo * 1.01, 1e-6))
        for ax, data, title in ((axs[1, 0], bp[:, 0], "Cramér–Rao bound per sample"),
                                (axs[1, 1], est[:, 0], "our estimator (Monte Carlo)")):
            im = ax.imshow(data.reshape(shape).T * 1e3, origin="lower", extent=ext, aspect="auto", norm=norm)
            ax.set(title=f"{title}, at the given force", xlabel="q1 [rad]", ylabel="q2 [rad]")
            fig.colorbar(im, ax=ax, label="mm along the link, 1σ (blank: refused)")
        med = int(np.argsort(bp[:, 0])[len(bp) // 2])
        d = np.degrees(np.asarray(bmaps["directions_rad"]))
        order = np.argsort(d)
        ax = axs[1, 2]
        ax.semilogy(d[order], bp[med, order] * 1e3, label="bound per sample")
        ax.semilogy(d[order], bmaps["bound_episode_m"][med, order] * 1e3,
                    label=f"bound over a {bmaps['hold_s']:g} s hold")
        ax.semilogy(d[order], est[med, order] * 1e3, "o", ms=3, label="our estimator (gap: refused)")
        fin = np.isfinite(est[med]) & np.isfinite(bp[med])
        if fin.any():                                  # the bound diverges along the link: clip
            top = 30 * np.nanmax(est[med][fin]) * 1e3
            ax.set_ylim(0.5 * np.nanmin(bmaps["bound_episode_m"][med]) * 1e3, top)
            for dd in d[~np.isfinite(est[med])]:
                ax.axvline(dd, color="0.6", lw=0.8, ls="--")
        ax.set(title="against the force direction, median posture (dashed: refused)",
               xlabel="force direction [deg from +x]", ylabel="mm along the link, 1σ")
        ax.legend(fontsize=8)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=110)
    plt.close(fig)
