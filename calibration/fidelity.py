"""Torque fidelity (paper Fig. 3): calibrated strain-gauge sensor vs motor-current estimate.

Ground truth τ(t) is the output-shaft torque on a loading trajectory (load 0–2 N·m in steps and
ramps while position control sweeps the joint, q(t) = q_a sin 2πf t).
Motor current (QDD, output side): the motor must supply
    τ_need = τ + τ_c tanh(ω/ω_s) + b ω + J_r N² ω̇
    N K_t i = τ_need / η   if τ_need ω ≥ 0 (motoring: gearbox losses on the way out)
    N K_t i = τ_need · η   otherwise (back-driven)
and the current-based estimate is the usual τ̂ = N K_t î, î = i + current-sense noise.
Strain gauge: τ → bridge chain (noise, quantization, hysteresis) → calibrated model τ̂(reading).
Metrics: R² = 1 − Σ(τ̂ − τ)²/Σ(τ − τ̄)², MAE = mean |τ̂ − τ|.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

PAPER = {"sensor": {"r2": 0.9998, "mae_Nm": 0.0286}, "motor_current": {"r2": 0.9609, "mae_Nm": 0.1319}}


@dataclass
class MotorModel:
    """QDD actuator (mjbots qdd100-like: mj5208 motor, single-stage 6:1 planetary).

    K_t = 8.27/Kv[rpm/V] with Kv ≈ 304 → 0.0272 N·m/A. Friction at the output, typical of a
    single-stage planetary QDD: Coulomb 0.15 N·m (≈1 % of its 16 N·m peak), viscous
    0.03 N·m·s/rad; gearbox efficiency 0.90 (single-stage planetary 0.90–0.97); rotor inertia
    6e-5 kg·m²; current-sense noise 0.05 A rms.
    """

    kt_Nm_per_A: float = 0.0272
    gear_ratio: float = 6.0
    coulomb_Nm: float = 0.15
    viscous_Nm_s_per_rad: float = 0.03
    stribeck_rad_per_s: float = 0.02        # tanh smoothing of the Coulomb sign
    efficiency: float = 0.90
    rotor_inertia_kg_m2: float = 6e-5
    current_noise_A: float = 0.05

    def current_A(self, tau_Nm, omega_rad_s, alpha_rad_s2):
        """Motor current that produces output torque ``tau_Nm`` (module docstring)."""
        need = (tau_Nm + self.coulomb_Nm * np.tanh(omega_rad_s / self.stribeck_rad_per_s)
                + self.viscous_Nm_s_per_rad * omega_rad_s
                + self.rotor_inertia_kg_m2 * self.gear_ratio**2 * alpha_rad_s2)
        motoring = need * omega_rad_s >= 0
        out = np.where(motoring, need / self.efficiency, need * self.efficiency)
        return out / (self.gear_ratio * self.kt_Nm_per_A)

    def estimate_Nm(self, current_A):
        """Naive current-based torque τ̂ = N K_t i."""
        return self.gear_ratio * self.kt_Nm_per_A * current_A


def loading_trajectory(duration_s: float = 40.0, rate_Hz: float = 500.0, peak_Nm: float = 2.0,
                       sweep_rad: float = 0.3, sweep_Hz: float = 0.25):
    """(t, τ, q, ω, α): smoothed load staircase 0 → peak → 0 while the joint sweeps."""
    t = np.arange(0.0, duration_s, 1.0 / rate_Hz)
    levels = peak_Nm * np.array([0, 0.25, 0.5, 0.75, 1.0, 0.6, 0.3, 0.0])
    k = np.minimum((t / duration_s * levels.size).astype(int), levels.size - 1)
    stair = levels[k]
    win = int(0.8 * rate_Hz)                     # 0.8 s ramps between levels
    kernel = np.ones(win) / win
    tau = np.convolve(np.pad(stair, (win // 2, win - win // 2 - 1), mode="edge"), kernel, "valid")
    w = 2 * np.pi * sweep_Hz
    q = sweep_rad * np.sin(w * t)
    return t, tau, q, sweep_rad * w * np.cos(w * t), -sweep_rad * w * w * np.sin(w * t)


def metrics(est, truth) -> dict:
    """R² and MAE of an estimate against the truth."""
    err = np.asarray(est) - np.asarray(truth)
    sst = np.sum((truth - np.mean(truth)) ** 2)
    return {"r2": float(1 - np.sum(err**2) / sst), "mae_Nm": float(np.mean(np.abs(err))),
            "rmse_Nm": float(np.sqrt(np.mean(err**2)))}


def torque_fidelity(sensor_model=None, *, motor: MotorModel | None = None, seed: int = 7,
                    spec=None, n_avg: int = 4, fit_kwargs=None) -> dict:
    """Run the comparison. ``sensor_model``: a SensorModel (default: emcee fit of a simulated
    paper link-1 session with 0.3 % FS hysteresis, then the same sensor on the trajectory)."""
    from calibration.simulate import paper_spec, sensor_readings, simulate_session

    rng = np.random.default_rng(seed)
    motor = motor or MotorModel()
    spec = spec or paper_spec(1, unload=True, hysteresis_Nm=0.003)
    if sensor_model is None:
        from calibration.fit import fit_session
        from calibration.store import calibration_payload, model_from_document
        session = simulate_session(spec, rng)
        fit = fit_session(session, "linear", seed=seed, **(fit_kwargs or {}))
        sensor_model = model_from_document(calibration_payload(fit, session))
    t, tau, q, omega, alpha = loading_trajectory()
    unloading = np.gradient(tau) < 0
    reading, _ = sensor_readings(spec, tau, rng, unloading=unloading, t_s=t, n_avg=n_avg)
    tau_sensor = sensor_model.torque(reading)
    current = motor.current_A(tau, omega, alpha) + rng.normal(0, motor.current_noise_A, t.size)
    tau_motor = motor.estimate_Nm(current)
    return {"t_s": t, "truth_Nm": tau, "sensor_Nm": tau_sensor, "motor_Nm": tau_motor,
            "sensor": metrics(tau_sensor, tau), "motor_current": metrics(tau_motor, tau),
            "paper": PAPER, "motor_params": asdict(motor),
            "sensor_hysteresis_Nm": spec.hysteresis_Nm, "n_avg": n_avg}
