"""`torquebench propagate`: what contact-localization error will this sensor design give on the leg?

A view over the stage graph (torquebench.pipeline: sensor_chain → error_map): the options make a
scene. A sensor configuration (bridge/ADC, ``scenes/paper_sensor.toml``) and a
strain per N·m (given, or from the bridge default) give the joint-torque noise σ_τ; a calibration
file gives the slope uncertainty (a systematic gain error); the FT sensor noise is Table II's.
``estimator.uncertainty`` then propagates them through the localizer over a grid of postures
(the paper's sweep: q ∈ [0, π]²), by Monte Carlo and to first order.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from torquebench.errors import InputError

HELP = "propagate sensor noise and calibration uncertainty into contact-localization error"
EXAMPLES = """\
torquebench propagate --grid 4 --draws 200
torquebench propagate --calibration calibration/data/paper_link1_cal.json --grid 6 --png out/position_error.png --json
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


def add_arguments(parser) -> None:
    parser.add_argument("--robot", type=Path, help="robot TOML (default: robots/paper_leg.toml)")
    parser.add_argument("--sensor", type=Path, help="sensor TOML (default: scenes/paper_sensor.toml)")
    parser.add_argument("--strain-per-Nm", type=float, dest="strain_per_Nm",
                        help="gauge strain per N·m of joint torque, 1/(N·m) (default: the sensor file's, or the paper's)")
    parser.add_argument("--torque-noise-Nm", type=float, dest="torque_noise_Nm",
                        help="joint-torque noise std per sample in N·m (default: from the sensor's bridge and ADC)")
    parser.add_argument("--calibration", type=Path, help="calibration JSON from `calibrate`: its slope uncertainty becomes a gain error")
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
                             "(postures × draws × 2 methods) (default: %(default)g)")
    parser.add_argument("--seed", type=int, default=0, help="Monte Carlo seed (default: %(default)s)")
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


def scene_from_args(args, robot, link, alpha, magnitude, direction):
    """The prediction scene of the command line: robot, [sensor] file, strain per N·m and
    calibration file as the chain's inputs, and the posture-grid settings."""
    from torquebench.scenes import ChainSpec, PredictionSpec, prediction_scene

    if args.sensor is not None and not Path(args.sensor).is_file():
        raise InputError(f"--sensor: {args.sensor}: file not found")
    chain = ChainSpec(strain_per_Nm=args.strain_per_Nm, sensor_file=args.sensor,
                      calibration_file=args.calibration)
    pred = PredictionSpec(link=link, alpha=alpha, magnitude_N=magnitude, direction_rad=direction,
                          grid=args.grid, draws=args.draws, seed=args.seed, sample_rate_Hz=args.rate,
                          gain_per_s=args.gain, ft_noise=tuple(_floats(args.ft_noise, 3, "--ft-noise")),
                          torque_noise_Nm=args.torque_noise_Nm, gain_error=args.gain_error)
    return prediction_scene(robot, chain, pred)


def run(args) -> int:
    from userio.errors import finite, seed

    seed(args.seed)                              # negative seeds → exit 2
    _finite_args(args)
    from estimator.robot import load_robot, paper_leg
    from torquebench import pipeline as P
    from torquebench.cache import Cache
    from torquebench.io import print_json

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
    work = float(args.grid) ** robot.n_links * args.draws * 2
    if work > finite(args.max_localizations, "--max-localizations", positive=True):
        raise InputError(f"--grid/--draws: {args.grid}^{robot.n_links} postures × {args.draws} draws × 2 "
                         f"methods = {work:.3g} localizations, above --max-localizations "
                         f"{args.max_localizations:.3g}; reduce them or raise the limit")
    if args.png and robot.n_links != 2:
        raise InputError("--png: the heat map is drawn for two-link robots only")
    from torquebench.outputs import Outputs

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
    if args.gain_error is None and args.calibration is not None:
        provenance["gain_error_source"] = str(args.calibration)

    results = {"torque_noise_std_Nm": float(noise.torque_std_Nm[0]),
               "gain_error_rel_std": float(noise.torque_gain_rel_std[0]),
               "ft_noise": noise.wrench_std.tolist(), "postures": em["postures"],
               "contact": {"link": link, "alpha": alpha, "force_N": magnitude, "direction_rad": direction},
               **provenance, "methods": dict(em["methods"])}
    if args.png:
        _heat_map(args.png, maps, axes)
        results["png"] = str(args.png)
    if args.json:
        print_json(results)
        return 0
    print(f"σ_τ = {results['torque_noise_std_Nm']:.4g} N·m ({provenance.get('torque_noise_source')}), "
          f"gain error {results['gain_error_rel_std']:.3g}, σ_FT = {results['ft_noise']}")
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
    return 0


def _heat_map(path: Path, maps: dict, axes) -> None:
    """Position-error maps over the (q1, q2) grid, one panel per method (two-link robots)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from torquebench.io import atomic_path

    fig, axs = plt.subplots(1, len(maps), figsize=(5 * len(maps), 4), constrained_layout=True)
    for ax, (method, values) in zip(np.atleast_1d(axs), maps.items()):
        grid = values.reshape(len(axes[0]), len(axes[1])) * 1e3
        im = ax.imshow(grid.T, origin="lower", extent=[0, math.pi, 0, math.pi], aspect="auto")
        ax.set(title=f"{method}: contact position RMS error", xlabel="q1 [rad]", ylabel="q2 [rad]")
        fig.colorbar(im, ax=ax, label="mm (blank: flagged)")
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=110)
    plt.close(fig)
