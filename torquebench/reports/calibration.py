"""Calibration report: paper eqs. 12–13 reproduced, emcee vs exact posterior, characterization,
torque fidelity vs motor current (paper Fig. 3). ``build(out_dir)`` → reports/calibration.md + PNGs."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np


def _fmt_pct(x):
    return "n/a" if x is None or not np.isfinite(x) else f"{x:.3f} %"


def build(out_dir: Path) -> list[Path]:
    from calibration.characterize import characterize
    from calibration.fidelity import MotorModel, torque_fidelity
    from calibration.fit import fit_session
    from calibration.plots import corner_plot, fidelity_plot, residual_plot
    from calibration.simulate import PAPER_FITS, paper_session
    from calibration.store import calibration_payload, model_from_document
    from userio.files import atomic_path, write_text_atomic

    out_dir = Path(out_dir)
    L = ["# Calibration: static loading, Bayesian fit, store, serial, torque fidelity", "",
         "All data here are **simulated** (`calibration.simulate`, fixed seeds) through "
         "`bridge.chain.paper_chain`, with dead-weight repeatability noise set so the expected R² "
         "is the paper's. Reading of eqs. 12–13: *y* is the bridge differential output in **mV**, "
         "*x* the applied mass in **grams** (1000 g → 11.5 mV, the paper's \"≈10 mV\" maximum); "
         "masses hang at l₁ = 0.205 m (our assumption, shared with `bridge`), so 1 kg ↔ 2.01 N·m "
         "and the slope is 5.72 mV per N·m. Priors: flat on slope/offset, p(σ) ∝ 1/σ.", "",
         "## Paper eqs. 12–13 reproduced (10 levels 10–1000 g × 5 repeats)", "",
         "| link | paper slope (mV/g) | ours (emcee, mean ± std) | 68 % interval | paper offset (mV) "
         "| ours | 68 % interval | paper R² | ours R² | τ | acceptance | fit time |",
         "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    fits = {}
    for link in (1, 2):
        s = paper_session(link)
        f = fit_session(s, seed=link)
        fits[link] = (s, f)
        q = f.quantiles()
        pf = PAPER_FITS[link]
        L.append(f"| {link} | {pf['slope_mV_per_g']} | {f.mean[0]:.5f} ± {f.std[0]:.5f} | "
                 f"[{q[0, 0]:.5f}, {q[2, 0]:.5f}] | {pf['offset_mV']} | {f.mean[1]:.4f} ± {f.std[1]:.4f} | "
                 f"[{q[0, 1]:.4f}, {q[2, 1]:.4f}] | {pf['r2']} | {f.exact.r2:.4f} | {f.tau_max:.1f} | "
                 f"{f.acceptance_fraction:.2f} | {f.elapsed_s:.2f} s |")
    slopes = "; ".join(f"link {k}: {fits[k][1].mean[0]:.5f} ± {fits[k][1].std[0]:.5f} mV/g (paper "
                       f"{PAPER_FITS[k]['slope_mV_per_g']})" for k in (1, 2))
    L[2:2] = [f"**Headline:** the Bayesian fit (emcee) of the paper's two simulated calibrations "
              f"recovers the slopes of eqs. 12–13, {slopes}", ""]
    L += ["", "The truth lies inside the 99.7 % interval in both fits (asserted by "
          "`tests/test_calibration.py`); across 300 simulated sessions the 68 % interval covers "
          "the truth 68 % of the time (also a test).", ""]

    s1, f1 = fits[1]
    corner_png, resid_png = out_dir / "calibration_corner.png", out_dir / "calibration_residuals.png"
    with atomic_path(corner_png) as tmp:
        corner_plot(f1, tmp, title="paper link 1 (simulated)")
    with atomic_path(resid_png) as tmp:
        residual_plot(s1, f1, tmp, title="link 1 residuals (linear fit)")

    # emcee vs exact, error vs run time
    ex = f1.exact
    L += ["## emcee vs the exact posterior: error against run time", "",
          "Exact reference: Student-t marginals (closed form, QR least squares). Error of the mean "
          "in units of the exact posterior std; error of the std relative. DE = differential-"
          "evolution move (default), stretch = emcee's default move. 256 walkers unless noted.", "",
          "| sampler | chain (τ multiples) | steps | τ | time | mean error (slope, offset) | std error (slope, offset) |",
          "|---|---|---|---|---|---|---|"]
    t0 = time.perf_counter()
    for _ in range(50):
        from calibration.posterior import design_matrix, exact_posterior
        exact_posterior(design_matrix(s1.mass_g, "linear"), s1.reading)
    t_exact = (time.perf_counter() - t0) / 50
    L.append(f"| closed form | – | – | – | {t_exact * 1e6:.0f} µs | 0 | 0 |")
    for moves, mult, walkers in (("de", 10, 256), ("de", 25, 256), ("de", 50, 256), ("de", 100, 256),
                                 ("de", 50, 64), ("stretch", 50, 256)):
        f = fit_session(s1, seed=11, moves=moves, tau_multiple=mult, n_walkers=walkers, min_steps=50)
        me = (f.mean[:2] - ex.beta) / ex.std
        se = f.std[:2] / ex.std - 1
        L.append(f"| {moves} ({walkers} walkers) | {mult} | {f.n_steps} | {f.tau_max:.1f} | {f.elapsed_s:.2f} s | "
                 f"{me[0]:+.2%}, {me[1]:+.2%} | {se[0]:+.2%}, {se[1]:+.2%} |")
    L += ["", "Monte Carlo error of the mean ≈ σ·√(τ/(walkers·steps)): 50 τ with 256 walkers gives "
          "≈ 0.9 % of σ (1-sigma). `python benchmarks/bench_calibration.py` times it over seeds.", "",
          f"![corner](calibration_corner.png)", "", f"![residuals](calibration_residuals.png)", ""]

    # characterization with hysteresis, creep, temperature drift
    sh = paper_session(1, unload=True, hysteresis_Nm=0.01, creep_frac=0.003, temp_ramp_C_per_s=0.002,
                       zero_tc_mV_per_C=0.002, seed=5)
    ch = characterize(sh)
    fh = fit_session(sh, "hysteresis", seed=5)
    L += ["## Characterization (simulated session with hysteresis, creep and drift)", "",
          "Injected: unloading branch +0.01 N·m, creep 0.3 % of each load step, temperature ramp "
          "0.002 °C/s with 2 µV/°C zero drift, loading and unloading × 5 repeats. Figures in % of "
          "full-scale output (FSO) of the best-fit straight line, as load-cell standards state them. "
          "The dead-weight repeatability noise that reproduces the paper's R² = 0.9991 is 0.12 mV "
          "≈ 1 % FS, which dominates non-linearity and repeatability here.", "",
          "| non-linearity | hysteresis | repeatability | FSO | hysteresis model: offset step |",
          "|---|---|---|---|---|",
          f"| {_fmt_pct(ch['nonlinearity_pct_fs'])} | {_fmt_pct(ch['hysteresis_pct_fs'])} | "
          f"{_fmt_pct(ch['repeatability_pct_fs'])} | {ch['fso']:.3f} mV | {fh.mean[2]:.4f} ± "
          f"{fh.std[2]:.4f} mV (injected {0.01 * 0.0115 / (9.81e-3 * 0.205):.4f}) |", ""]

    # fidelity
    res = torque_fidelity(seed=7)
    fid_png = out_dir / "calibration_fidelity.png"
    with atomic_path(fid_png) as tmp:
        fidelity_plot(res, tmp)
    mp = res["motor_params"]
    s, m, P = res["sensor"], res["motor_current"], res["paper"]
    L += ["## Torque fidelity vs motor current (paper Fig. 3)", "",
          "Loading trajectory: 40 s, load staircase 0 → 2 N·m → 0 with 0.8 s ramps while position "
          "control sweeps the joint ±0.3 rad at 0.25 Hz. Sensor: the calibrated link-1 model "
          "(emcee) on 4-sample averages (1 kHz from 4 kSps), 0.003 N·m hysteresis. Motor current: "
          f"K_t = {mp['kt_Nm_per_A']} N·m/A (mj5208, 8.27/Kv with Kv ≈ 304 rpm/V), N = {mp['gear_ratio']:g}, "
          f"Coulomb {mp['coulomb_Nm']} N·m and viscous {mp['viscous_Nm_s_per_rad']} N·m·s/rad at the "
          f"output, efficiency {mp['efficiency']}, rotor inertia {mp['rotor_inertia_kg_m2']} kg·m², "
          f"current noise {mp['current_noise_A']} A. These are typical single-stage planetary QDD "
          "values (Coulomb ≈ 1 % of the 16 N·m peak; efficiency 0.90–0.97), chosen before running, "
          "not fitted to the paper; the sweep below shows how the result depends on them.", "",
          "| estimate | R² (ours) | MAE (ours) | R² (paper) | MAE (paper) |", "|---|---|---|---|---|",
          f"| strain-gauge sensor | {s['r2']:.5f} | {s['mae_Nm']:.4f} N·m | {P['sensor']['r2']} | "
          f"{P['sensor']['mae_Nm']} N·m |",
          f"| motor current | {m['r2']:.4f} | {m['mae_Nm']:.4f} N·m | {P['motor_current']['r2']} | "
          f"{P['motor_current']['mae_Nm']} N·m |", "",
          "Motor-current MAE (N·m) against Coulomb friction and efficiency (same trajectory):", "",
          "| Coulomb \\ efficiency | 0.97 | 0.95 | 0.90 |", "|---|---|---|---|"]
    grid = []
    for tc in (0.05, 0.10, 0.15):
        row = []
        for eta in (0.97, 0.95, 0.90):
            r = torque_fidelity(sensor_model=_shared_model(),
                                motor=MotorModel(coulomb_Nm=tc, efficiency=eta), seed=7)
            row.append(f"{r['motor_current']['mae_Nm']:.3f} (R² {r['motor_current']['r2']:.3f})")
            grid.append((abs(r["motor_current"]["mae_Nm"] - P["motor_current"]["mae_Nm"]), tc, eta,
                         r["motor_current"]["mae_Nm"], r["motor_current"]["r2"]))
        L.append(f"| {tc} N·m | " + " | ".join(row) + " |")
    _, tc_b, eta_b, mae_b, r2_b = min(grid)
    L += ["", "Our sensor does better than the paper's (MAE "
          f"{s['mae_Nm']:.4f} vs 0.0286 N·m) because the simulation holds only the error sources "
          "modelled (chain noise, quantization, hysteresis, calibration uncertainty): no cross-talk "
          "from off-axis loads, mounting or thermal gradients. Closest grid point to the paper's "
          f"motor-current MAE: Coulomb {tc_b} N·m, efficiency {eta_b} (MAE {mae_b:.3f} N·m, "
          f"R² {r2_b:.3f}); our default (0.15 N·m, 0.90) has more friction than the paper's "
          "actuator evidently had.", "", "![fidelity](calibration_fidelity.png)", "",
          "## Serial frame (Arduino Due sketch `calibration/firmware/torquebench_adc`)", "",
          "`A5 5A | seq u16 BE | n_ch u8 | n_ch × int24 BE | CRC-16/CCITT-FALSE BE` over seq…samples "
          "(poly 0x1021, init 0xFFFF; check(\"123456789\") = 0x29B1). The parser resynchronizes at "
          "any byte, counts corrupted candidates and lost sequence numbers; `acquire` writes raw "
          "bytes to disk before parsing.", ""]
    md = out_dir / "calibration.md"
    write_text_atomic(md, "\n".join(L))
    return [md, corner_png, resid_png, fid_png]


_MODEL_CACHE = {}


def _fit_pair():
    from calibration.fit import fit_session
    from calibration.simulate import paper_session
    s = paper_session(1, unload=True, hysteresis_Nm=0.003, seed=7)
    return fit_session(s, seed=7), s


def _shared_model():
    """One calibrated link-1 sensor model reused across the friction sweep."""
    if "m" not in _MODEL_CACHE:
        from calibration.store import calibration_payload, model_from_document
        _MODEL_CACHE["m"] = model_from_document(calibration_payload(*_fit_pair()))
    return _MODEL_CACHE["m"]
