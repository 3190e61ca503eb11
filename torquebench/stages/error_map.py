"""The localization error over a posture grid (``torquebench propagate``).

    error_map   chain, calibration → error_map (Monte Carlo + first order over a posture grid)
"""

from __future__ import annotations

import math

import numpy as np

from torquebench.stages.cachekey import canon, file_hash
from torquebench.stages.declaration import Stage
from torquebench.stages.scoring import METHODS


def calibration_noise(cal, chain=None) -> tuple[float, str, list]:
    """σ_τ of one torque reading from a calibration: its reading noise through its slope,
    σ_τ = σ_reading / |slope| · 10⁻³ g L (N·m), and how it compares with the sensor chain's noise
    budget and sensitivity (a warning when they differ by more than 2×: another sensor, another
    unit, or readings averaged over several ADC samples)."""
    i = list(cal.coef_names).index("slope")
    slope = abs(float(cal.coef_mean[i]))
    per_Nm = slope / cal._torque_per_g()                 # reading units per N·m
    sigma = float(cal.sigma) / per_Nm
    source = (f"the calibration's reading noise ({cal.sigma:.3g} {cal.reading_unit or 'reading units'} "
              f"through its slope, {cal.source})")
    warnings = []
    if chain is not None:
        ratio = sigma / chain.noise_std_Nm
        if not 0.5 <= ratio <= 2.0:
            warnings.append(f"the calibration's σ_τ {sigma:.3g} N·m is {ratio:.2g}× the sensor chain's "
                            f"{chain.noise_std_Nm:.3g} N·m: is the chain (sensor file, strain per N·m) "
                            f"this sensor's, or were its readings averages of several samples?")
        if cal.reading_unit == "counts":
            s_ratio = per_Nm / abs(chain.counts_per_Nm)
            if not 0.5 <= s_ratio <= 2.0:
                warnings.append(f"the calibration's sensitivity {per_Nm:.4g} counts/N·m is {s_ratio:.2g}× "
                                f"the sensor chain's {abs(chain.counts_per_Nm):.4g}")
    return sigma, source, warnings


def run_error_map(scene, inp, seed=None):
    """Localization error over the posture grid q ∈ [0, π]^n (estimator.uncertainty): Monte Carlo
    and first order, per method, with σ_τ from the sensor chain (or given), the calibration's
    relative slope std as a gain error (or given), the FT noise and the robot's parameter
    uncertainty (given, else the robot file's identification or declared uncertainty)."""
    from estimator.uncertainty import SensorNoise, first_order, monte_carlo

    pr, robot = scene.prediction, scene.robot
    cal, chain = inp.get("calibration"), inp.get("chain")
    sigma_tau, tau_source, warnings = pr.torque_noise_Nm, "given", []
    if sigma_tau is None and cal is not None and cal.lever_arm_m is not None:
        sigma_tau, tau_source, warnings = calibration_noise(cal, chain)
    elif sigma_tau is None:
        sigma_tau, tau_source = chain.noise_std_Nm, "the sensor chain's noise budget"
    gain_error = pr.gain_error
    if gain_error is None and cal is not None:
        i = list(cal.coef_names).index("slope")
        gain_error = math.sqrt(cal.coef_cov[i, i]) / abs(cal.coef_mean[i])
    noise = SensorNoise(torque_std_Nm=sigma_tau, wrench_std=list(pr.ft_noise),
                        torque_gain_rel_std=gain_error or 0.0, sample_rate_Hz=pr.sample_rate_Hz,
                        gain_per_s=pr.gain_per_s)
    force = pr.magnitude_N * np.array([math.cos(pr.direction_rad), math.sin(pr.direction_rad)])
    from estimator.model import ModelUncertainty
    from estimator.model_error import resolve

    mu = pr.model_uncertainty
    cov, cov_source = resolve(robot, None if mu is None else
                              (ModelUncertainty.uniform(mu) if mu > 0 else False))
    axes = [np.linspace(0.0, math.pi, pr.grid)] * robot.n_links
    postures = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, robot.n_links)
    out = {"noise": noise, "axes": axes, "postures": len(postures), "methods": {}, "maps": {},
           "model_uncertainty_source": cov_source, "torque_noise_source": tau_source,
           "warnings": warnings}
    for method in METHODS:
        mc = monte_carlo(robot, postures, pr.link, pr.alpha, force, noise, draws=pr.draws,
                         rng=pr.seed, method=method, parameter_cov=cov)
        fo = first_order(robot, postures, pr.link, pr.alpha, force, noise, method=method,
                         parameter_cov=cov)
        usable = mc.flagged_fraction < 0.05
        pos = mc.position_rms_m[usable]
        ratio = mc.position_rms_m[usable] / fo.position_rms_m[usable]
        worst = int(np.flatnonzero(usable)[np.argmax(mc.position_p95_m[usable])]) if pos.size else None
        out["methods"][method] = {
            "position_rms_median_m": float(np.median(pos)) if pos.size else None,
            "position_rms_median_m_error_estimate":
                float(np.median(mc.position_rms_se_m[usable])) if pos.size else None,
            "position_rms_median_m_error_method":
                f"Monte Carlo standard error (1 sigma, delta method), median over postures, {pr.draws} draws",
            "position_rms_max_m": float(np.max(pos)) if pos.size else None,
            "position_p95_max_m": float(np.max(mc.position_p95_m[usable])) if pos.size else None,
            "position_p95_max_m_error_estimate":
                float(mc.position_p95_se_m[worst]) if pos.size else None,
            "position_p95_max_m_error_method":
                f"Monte Carlo standard error (1 sigma) of the 95th percentile at the worst posture, "
                f"from the binomial spread of order statistics, {pr.draws} draws",
            "force_rms_median_N": float(np.median(mc.force_rms_N[usable])) if pos.size else None,
            "flagged_postures": int((~usable).sum()),
            "monte_carlo_over_first_order_median": float(np.median(ratio)) if pos.size else None,
        }
        out["maps"][method] = np.where(usable, mc.position_rms_m, np.nan)
    out["bounds"] = bound_maps(robot, postures, pr, sigma_tau)
    return out


def bound_maps(robot, postures, pr, sigma_tau) -> dict:
    """The Cramér–Rao bound and our estimator's predicted error over the postures × force
    directions (estimator.bound_maps), the scene's direction first; {} with a reason when a zero
    σ leaves nothing to whiten."""
    from estimator.bound_maps import localization_maps
    from estimator.noise import NoiseModel

    if not (sigma_tau > 0 and all(v > 0 for v in pr.ft_noise)):
        return {"reason": "a zero sensor σ: the residual cannot be whitened, no bound"}
    dirs = pr.direction_rad + 2 * math.pi * np.arange(pr.directions) / pr.directions
    dirs = (dirs + math.pi) % (2 * math.pi) - math.pi
    noise = NoiseModel(torque_sigma_Nm=[sigma_tau], ft_sigma=list(pr.ft_noise))
    m = localization_maps(robot, postures, pr.link, pr.alpha, pr.magnitude_N, dirs, noise,
                          pr.gain_per_s, 1.0 / pr.sample_rate_Hz, pr.hold_s,
                          draws=min(pr.draws, 200), seed=pr.seed)
    m["directions_rad"] = dirs
    return m



def _uses(scene, art):
    if art == "chain":
        return scene.prediction.torque_noise_Nm is None
    return scene.prediction.gain_error is None and scene.chain.calibration_file is not None


STAGES = (
    Stage("error_map", "error_map", "Monte Carlo + first-order localization error over a posture grid",
          run_error_map, needs=("chain?", "calibration?"), reads=("prediction", "robot", "calibration.file"),
          params=lambda scene, seed: {"prediction": canon(scene.prediction), "robot": canon(scene.robot),
                                      "cal": file_hash(scene.chain.calibration_file)},
          feasible=lambda scene: None if scene.prediction is not None else
          "no posture-grid prediction settings (`propagate` builds them from its options)",
          uses=_uses),
)
