"""`torquebench demo`: the shipped scene ``paper_floating_link2`` through the stage graph.

The paper's Table III test 2 (7 N on link 2 at α = 0.8, −π/3, floating base): the joint torques
go through the bridge/ADC sensor model (torquebench.pipeline.run_sensor_chain: the paper's, or the
``--flexure`` design's strain per N·m in the same model) as ADC counts and back; observer +
``dynamic`` and ``paper`` localization are scored against the truth over the collision phase
(torquebench.pipeline.collision_phase_errors) beside the Monte Carlo prediction for that sensor
and posture. Results are cached (a second run takes seconds). Writes the log, its truth and both
estimates to --out-dir (default out/demo).
"""

from __future__ import annotations

import sys
from pathlib import Path

HELP = "run the workbench end to end on the paper's leg (no hardware, no input)"
EXAMPLES = """\
torquebench demo
torquebench demo --out-dir out/demo2 --seed 3 --flexure designs/paper_disc.toml
"""
SCENE = "paper_floating_link2"


def add_arguments(parser) -> None:
    parser.add_argument("--out-dir", type=Path, default=Path("out/demo"),
                        help="directory for the demo's files, created if missing: log.csv, log.truth.csv, "
                             "estimate_dynamic.csv, estimate_paper.csv; a later demo replaces the files "
                             "an earlier one wrote there, never a file of yours without --force "
                             "(default: %(default)s)")
    parser.add_argument("--force", action="store_true",
                        help="replace files of those names in --out-dir that the demo did not write")
    parser.add_argument("--seed", type=int, default=None,
                        help="sensor-noise seed (default: the scene's, so that the demo and "
                             "`torquebench run` of its scene give the same numbers)")
    parser.add_argument("--flexure", type=Path, default=None, metavar="DESIGN.toml",
                        help="take the torque sensor's strain per N·m from this flexure's FEM "
                             "(e.g. designs/paper_disc.toml) instead of the paper's calibration")


def run(args) -> int:
    from userio.errors import seed

    seed(args.seed)                              # negative seeds → exit 2
    from dataclasses import replace

    from torquebench.outputs import scene_plan
    from torquebench.scenes import load_scene, scene_path
    from userio.files import check_input

    scene = load_scene(scene_path(SCENE))
    if args.flexure is not None:
        check_input(args.flexure, "--flexure", what="flexure design TOML")
        scene = replace(scene, chain=replace(scene.chain, flexure_design=args.flexure.resolve()))
    plan = scene_plan(scene, force=args.force)
    out_dir = plan.directory("--out-dir", args.out_dir)
    for name in FILES:
        plan.file_in("--out-dir", out_dir, name)
    with plan.active():                      # checked now; every write obeys it
        return _demo(args, scene, out_dir)


FILES = ("log.csv", "log.truth.csv", "estimate_dynamic.csv", "estimate_paper.csv")


def _demo(args, scene, out_dir) -> int:
    from estimator.log import SensorLog, write_log
    from estimator.sim.output import truth_csv
    from torquebench import pipeline as P
    from torquebench.cache import Cache
    from torquebench import formatting as fmt
    from torquebench.io import print_json
    from userio.files import write_text_atomic

    say = (lambda *a: print(*a, file=sys.stderr)) if args.json else print
    arts, timing = P.execute(scene, ["localization_error", "predicted_error"], Cache(), seed=args.seed)
    chain, K = arts["chain"], scene.estimator.gain_per_s
    results = {"scene": SCENE, "methods": {}, "torque_noise_std_Nm": chain.noise_std_Nm,
               "stages": [{"stage": n, "action": a, "time_s": t} for n, a, t in timing]}
    if "flexure" in arts:
        fx = arts["flexure"]
        results["flexure"] = {"design_file": str(args.flexure), **fx}
        say(f"0. flexure: {args.flexure}: {fx['gauge_strain_per_Nm']:.4g}{fmt.pm(fx, 'gauge_strain_per_Nm')} "
            f"strain/N·m at the gauges (P2 FEM, 3 mesh levels, {fx['dofs']} DOFs at the answer), "
            f"safety factor {fx['safety_factor']:.2f}")
    say(f"1. sensor: bridge/ADC chain, {fmt.sensor_text(chain)} (the same model in the simulation)")
    e = scene.estimator
    rate = f"{e.false_alarm_rate[0]:g}/{e.false_alarm_rate[1]}"
    results["detection"] = {
        "dynamic": f"chi-square at {rate} on the residual whitened by the scene's sensor noise"
                   if e.threshold is None else f"‖r‖ > {e.threshold:g}",
        "paper": f"‖r‖ > {e.threshold if e.threshold is not None else 0.06:g}",
        "residual_noise_source": arts["estimates"].get("noise_source")}
    say(f"   detection: dynamic {results['detection']['dynamic']}; paper {results['detection']['paper']}")
    rd, tq, tr = arts["readings"], arts["torques"], arts["truth"]
    free = P.contact_free_mask(rd["t"][arts["estimates"]["kept"]], scene.sim.pokes, K)
    log = SensorLog(t=rd["t"], q=rd["q"], dq=rd["dq"], tau_Nm=tq["tau_Nm"], wrench=rd["wrench"],
                    floating=rd["floating"])
    say(f"2. robot: {SCENE}: {len(log.t)} samples; stages: "
        + ", ".join(f"{n} {a}" for n, a, _ in timing))
    write_log(log, out_dir / "log.csv")
    write_text_atomic(out_dir / "log.truth.csv", truth_csv(tr["truth"]))
    for method in P.METHODS:
        est = arts["estimates"][method]
        write_text_atomic(out_dir / f"estimate_{method}.csv", est.to_frame().to_csv(index=False))
        m = dict(arts["localization_error"][method])
        m["contact_free_flagged_fraction"] = float(est.contact[free].mean())
        pr = arts["predicted_error"][method]
        m["predicted_position_rms_m"] = pr["position_rms_m"]
        m["predicted_position_rms_m_error_estimate"] = pr["position_rms_m_error_estimate"]
        m["predicted_position_rms_m_error_method"] = pr["position_rms_m_error_method"]
        results["methods"][method] = m
    say("3–4. estimate vs truth over the collision phase, and the Monte Carlo prediction:")
    say(f"   {'method':8s} {'mean |p| err':>13s} {'RMS |p| err':>12s} {'predicted RMS':>14s} {'mean |F| err':>13s}")
    for method, m in results["methods"].items():
        say(f"   {method:8s} {fmt.mm(m['position_error_mean_m']):>13s} {fmt.mm(m['position_error_rms_m']):>12s} "
            f"{fmt.mm(m['predicted_position_rms_m']):>14s} {m['force_error_mean_N'] or float('nan'):>11.3f} N")
    say("   paper's Table III test 2: mean |p| error 2 mm, |F| 0.121 N.")
    say("   contact-free samples flagged as contact (before the poke, and from 10/K after release): "
        + ", ".join(f"{k} {100 * m['contact_free_flagged_fraction']:.2f} %"
                    for k, m in results["methods"].items()))
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
