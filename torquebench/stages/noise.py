"""The sensor noise the detector whitens with: the scene's NoiseModel (estimator.noise) for the
readings its estimates see, with where every σ came from."""

from __future__ import annotations

import numpy as np

from userio.errors import InputError


def _torque_from_counts(scene) -> bool:
    """Whether the estimates' torques are the simulated ADC codes of the sensor chain (a simulated
    scene's raw_counts, whatever [sensors].torque_model says), read back through the calibration."""
    return scene.sim is not None


def scene_noise_model(scene, chain=None, calibration=None, readings: str = "counts"):
    """The estimator's NoiseModel (estimator.noise) for the readings the scene's estimates see,
    with ``source`` naming where every σ came from; None when the scene states no sensors (a
    recorded log without counts columns: the estimator's own default then applies and says so).

    σ_τ per sample: torques read from ADC counts (every simulated scene's raw_counts, whatever
    [sensors].torque_model says) carry the chain's white noise
    σ_c = σ_τ,true · counts_per_Nm,true (true chain = the chain at true_gain_factor × strain),
    read back through the reader's slope: σ_τ = σ_c / (counts per N·m of the calibration, or of
    the nominal chain without one). The calibration's slope uncertainty is NOT white noise: it
    scales every sample of a run by the same factor (a bias of the torque, not a per-sample
    scatter), so it does not enter the detector's covariance (it enters predicted_error).
    readings="log": the log `simulate` writes (sensor_log): σ_τ = the chain's noise_std_Nm for
    torque_model "bridge" (estimator.sim.sensors.measure reads through ``chain``), else
    sensors.torque_noise_Nm.
    FT σ, joint-rate σ and encoder counts: the scene's [sensors] (what raw_counts draws).
    Raises InputError when a σ is zero (a zero-noise channel cannot be whitened)."""
    from dataclasses import replace

    from estimator.noise import NoiseModel

    sim = scene.sim
    if sim is None:                       # a recorded log states no sensor noise
        return None
    parts = []
    if readings == "log":
        if sim.sensors.torque_model == "bridge":
            from torquebench.stages.sensor import run_sensor_chain

            chain = chain if chain is not None else run_sensor_chain(scene, {})
            sigma_tau = chain.noise_std_Nm
            parts.append(f"τ σ {sigma_tau:.3g} N·m = the bridge chain's noise_std_Nm")
        else:
            sigma_tau = sim.sensors.torque_noise_Nm
            parts.append("τ σ from sensors.torque_noise_Nm")
    elif chain is not None:
        true = replace(chain, strain_per_Nm=chain.strain_per_Nm * scene.chain.true_gain_factor)
        sigma_counts = true.noise_std_Nm * abs(true.counts_per_Nm)
        if calibration is not None:
            read = np.asarray(calibration.torque(np.array([0.0, 1.0])), float)
            per_count, by = abs(read[1] - read[0]), "the fitted calibration"
        else:
            per_count, by = 1.0 / abs(chain.counts_per_Nm), "the nominal chain"
        sigma_tau = sigma_counts * per_count
        parts.append(f"τ σ {sigma_tau:.3g} N·m = sensor chain noise {sigma_counts:.3g} counts "
                     f"(gain factor {scene.chain.true_gain_factor:g}) read through {by}")
    else:
        sigma_tau = sim.sensors.torque_noise_Nm
        parts.append("τ σ from sensors.torque_noise_Nm")
    sensors = sim.sensors
    parts.append("FT σ from sensors.ft_noise")
    if sensors.velocity_noise_rad_per_s:
        parts.append("q̇ σ from sensors.velocity_noise_rad_per_s")
    if sensors.encoder_counts:
        parts.append("encoder quantization from sensors.encoder_counts")
    sigmas = [sigma_tau, *np.asarray(sensors.ft_noise, float)]
    if not all(np.isfinite(v) and v > 0 for v in sigmas):
        raise InputError(f"{scene.path}: sensors: a zero σ (τ σ {sigma_tau:g} N·m, ft_noise "
                         f"{np.asarray(sensors.ft_noise).tolist()}) cannot whiten the residual "
                         "for the chi-square detector; give every σ > 0 or set [estimator] threshold")
    return NoiseModel(torque_sigma_Nm=[sigma_tau], ft_sigma=sensors.ft_noise,
                      velocity_sigma_rad_per_s=sensors.velocity_noise_rad_per_s,
                      encoder_counts=sensors.encoder_counts,
                      source=f"scene {scene.name}: " + "; ".join(parts))

