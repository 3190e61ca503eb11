"""`torquebench demo`: the workbench end to end on the paper's leg, no hardware, no input.

0. (``--flexure DESIGN.toml``) the flexure's FEM gives the gauge strain per N·m (flexure);
1. sensor: the paper's bridge/ADC chain → joint-torque noise σ_τ (bridge);
2. robot: the paper's Table III test 2 (7 N on link 2 at α = 0.8, −π/3, floating base), simulated
   with that torque sensor and Table II FT noise (estimator.sim);
3. estimate: observer + `dynamic` and `paper` localization, errors against the truth;
4. predict: the Monte Carlo localization error for that sensor at that posture (estimator.uncertainty),
   beside what the estimate measured.
Writes the log, its truth and both estimates to --out-dir (default out/demo).
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np

HELP = "run the workbench end to end on the paper's leg (no hardware, no input)"
EXAMPLES = """\
torquebench demo
torquebench demo --out-dir out/demo2 --seed 3 --flexure scenes/paper_disc.toml
"""
SCENE = "paper_floating_link2"


def add_arguments(parser) -> None:
    parser.add_argument("--out-dir", type=Path, default=Path("out/demo"),
                        help="directory for the demo's files, created if missing; the demo replaces its own four files there (log.csv, log.truth.csv, estimate_dynamic.csv, estimate_paper.csv) (default: %(default)s)")
    parser.add_argument("--seed", type=int, default=1, help="sensor-noise seed (default: %(default)s)")
    parser.add_argument("--flexure", type=Path, default=None, metavar="DESIGN.toml",
                        help="take the torque sensor's strain per N·m from this flexure's FEM "
                             "(e.g. scenes/paper_disc.toml) instead of the paper's calibration")


def _errors(est, truth, t_on, gain_per_s):
    """Mean |p| and |F| error over the collision phase (poke on, t ≥ t_on + 5/K), scored samples."""
    phase = (truth["link"] > 0) & (truth["t"] >= t_on + 5.0 / gain_per_s)
    ok = phase & np.isfinite(est.px)
    dp = np.hypot(est.px[ok] - truth["px"][ok], est.pz[ok] - truth["pz"][ok])
    dF = np.hypot(est.Fx[ok] - truth["Fx"][ok], est.Fz[ok] - truth["Fz"][ok])
    return {"position_error_mean_m": float(dp.mean()) if dp.size else None,
            "position_error_rms_m": float(np.sqrt(np.mean(dp ** 2))) if dp.size else None,
            "force_error_mean_N": float(dF.mean()) if dF.size else None,
            "scored_samples": int(ok.sum()), "collision_samples": int(phase.sum())}


def run(args) -> int:
    from userio.errors import seed

    seed(args.seed)                              # issue 16: negative seeds → exit 2
    from bridge.chain import paper_chain
    from estimator.log import write_log
    from estimator.pipeline import estimate
    from estimator.uncertainty import SensorNoise, monte_carlo
    from torquebench.commands.simulate import run_scene
    from torquebench.errors import InputError
    from torquebench.io import print_json, write_text_atomic
    from torquebench.scenes import load_scene, scene_path
    from estimator.sim.output import truth_csv

    from torquebench.outputs import prepare_dir

    out_dir = prepare_dir(args.out_dir, "--out-dir")
    say = (lambda *a: print(*a, file=sys.stderr)) if args.json else print

    scene = load_scene(scene_path(SCENE))
    results = {"scene": SCENE, "methods": {}}
    if args.flexure is None:
        chain = paper_chain()
        say(f"1. sensor: paper bridge/ADC chain, {chain.strain_per_Nm:.3g} strain/N·m (paper's calibration)"
            f" → σ_τ = {chain.noise_std_Nm:.4f} N·m per sample")
    else:
        from dataclasses import replace

        from flexure.analysis import analyze
        from flexure.design import load_design

        fx, _ = analyze(load_design(args.flexure))
        if fx.get("nan_reason"):
            raise InputError(f"--flexure: {args.flexure}: no trustworthy gauge strain ({fx['nan_reason']})")
        chain = paper_chain(fx["gauge_strain_per_Nm"])
        say(f"0. flexure: {args.flexure}: {fx['gauge_strain_per_Nm']:.3g} strain/N·m at the gauges "
            f"(P2 FEM, {fx['dofs']} DOFs), safety factor {fx['safety_factor']:.2f}")
        say(f"1. sensor: paper bridge/ADC chain on that flexure → σ_τ = {chain.noise_std_Nm:.4f} N·m per "
            "sample (simulated as Gaussian of that σ)")
        scene = replace(scene, sim=replace(scene.sim, sensors=replace(
            scene.sim.sensors, torque_model="gaussian", torque_noise_Nm=chain.noise_std_Nm)))
        results["flexure"] = {k: fx[k] for k in ("design_file", "gauge_strain_per_Nm",
                                                  "sensitivity_mV_per_V_per_Nm", "safety_factor", "dofs")}
    sigma_tau = chain.noise_std_Nm
    results["torque_noise_std_Nm"] = sigma_tau

    log, truth, stats = run_scene(scene, seed=args.seed)
    cfg = scene.sim
    poke = cfg.pokes[0]
    say(f"2. robot: {SCENE}: {len(log.t)} samples, {stats.get('integrator')} in {stats['run_time_s']:.2f} s")
    write_log(log, out_dir / "log.csv")
    write_text_atomic(out_dir / "log.truth.csv", truth_csv(truth))

    K = scene.estimator.gain_per_s
    for method in ("dynamic", "paper"):
        est = estimate(cfg.robot, log, method=method, gain_per_s=K, threshold=scene.estimator.threshold)
        with_out = out_dir / f"estimate_{method}.csv"
        write_text_atomic(with_out, est.to_frame().to_csv(index=False))
        results["methods"][method] = _errors(est, truth, poke.t_on_s, K)

    q_hold = np.asarray(cfg.controller.q0_rad, float)
    force = poke.magnitude_N * np.array([math.cos(poke.direction_rad), math.sin(poke.direction_rad)])
    noise = SensorNoise(torque_std_Nm=sigma_tau, wrench_std=cfg.sensors.ft_noise,
                        torque_gain_rel_std=0.0, sample_rate_Hz=cfg.sensors.sample_rate_Hz, gain_per_s=K)
    for method in ("dynamic", "paper"):
        mc = monte_carlo(cfg.robot, q_hold, poke.link, poke.alpha, force, noise, draws=2000, rng=0, method=method)
        results["methods"][method]["predicted_position_rms_m"] = float(mc.position_rms_m[0])
    say("3–4. estimate vs truth over the collision phase, and the Monte Carlo prediction (static, sensor noise only):")
    say(f"   {'method':8s} {'mean |p| err':>13s} {'RMS |p| err':>12s} {'predicted RMS':>14s} {'mean |F| err':>13s}")
    for method, m in results["methods"].items():
        mm = lambda v: f"{v * 1e3:.2f} mm" if v is not None else "—"   # noqa: E731
        say(f"   {method:8s} {mm(m['position_error_mean_m']):>13s} {mm(m['position_error_rms_m']):>12s} "
            f"{mm(m['predicted_position_rms_m']):>14s} {m['force_error_mean_N'] or float('nan'):>11.3f} N")
    say("   paper's Table III test 2: mean |p| error 2 mm, |F| 0.121 N.")
    files = {"log.csv": "the simulated sensor log (t, base and joint states, tau1, tau2, Fx, Fz, My; SI units)",
             "log.truth.csv": "the contact really applied, per sample (t, link, alpha, Fx, Fz, px, pz)",
             "estimate_dynamic.csv": "the 'dynamic' estimate per sample (t, contact, link, alpha, Fx, Fz, px, pz, rnorm)",
             "estimate_paper.csv": "the 'paper' (quasi-static, eqs. 6-9) estimate, same columns"}
    say(f"Files in {out_dir}/ (formats: docs/conventions.md):")
    for name, what in files.items():
        say(f"   {name:<21s} {what}")
    results["out_dir"] = str(out_dir)
    results["files"] = {str(out_dir / name): what for name, what in files.items()}
    if args.json:
        print_json(results)
    return 0

