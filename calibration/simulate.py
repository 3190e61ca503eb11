"""Simulated static-loading sessions through the ``bridge`` sensor chain, with known truth.

Reading of one load level (bridge differential output referred to the bridge, in mV):

    τ_eff  = m g L (1 + k_span ΔT) + h·[unloading] + c_creep Δτ_step (1 − e^(−t_s/τ_c))
    V      = chain.bridge_volts(chain.torque_from_counts(chain.counts(τ_eff, rng)))  (mean of n_avg)
    r_mV   = polarity · 1e3 · V + offset_mV + k_zero ΔT + q m² + ε,   ε ~ N(0, σ_rep²)

``chain`` is ``bridge.chain.paper_chain(strain_per_Nm=...)`` with the strain per N·m set so that
the sensitivity is ``slope_mV_per_g`` at lever arm L. ``polarity`` = sign(slope) (gauge leads
swapped gives the paper's negative eq. 13). The lever arm defaults to l_1 = 0.205 m (masses
hung at the end of the thigh: 1 kg → 2.0 N·m, the 0–2 N·m range of Fig. 3), the same
assumption as ``bridge.chain``; the paper does not state it. ΔT = ramp·t (temperature drift). σ_rep is the
repeatability noise of placing a dead weight (set from the paper's R² by :func:`paper_session`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from calibration.session import G_STANDARD_M_PER_S2, Session

PAPER_FITS = {  # eqs. 12–13: reading (mV) = slope·mass (g) + offset, with R²
    1: {"slope_mV_per_g": 0.0115, "offset_mV": 5.0069, "r2": 0.9991},
    2: {"slope_mV_per_g": -0.0108, "offset_mV": -2.3260, "r2": 0.9999},
}
PAPER_MASSES_G = (10.0, 20.0, 50.0, 100.0, 200.0, 300.0, 500.0, 700.0, 850.0, 1000.0)


@dataclass
class SessionSpec:
    """Parameters of a simulated session (truth)."""

    slope_mV_per_g: float = 0.0115
    offset_mV: float = 5.0069
    lever_arm_m: float = 0.205
    masses_g: tuple = PAPER_MASSES_G
    repeats: int = 5
    unload: bool = False                 # each repeat also walks down the levels
    quad_mV_per_g2: float = 0.0          # non-linearity
    hysteresis_Nm: float = 0.0           # torque-equivalent offset of the unloading branch
    creep_frac: float = 0.0              # creep amplitude per N·m of load step
    creep_tau_s: float = 30.0
    settle_s: float = 5.0
    temp_ramp_C_per_s: float = 0.0
    zero_tc_mV_per_C: float = 0.0
    span_tc_per_C: float = 0.0
    repeat_noise_mV: float = 0.0
    n_avg: int = 256                     # ADC samples averaged per reading
    sample_rate_Hz: float = 4000.0
    sensor_id: str = "sim"
    chain_overrides: dict = field(default_factory=dict)


def sensor_chain(sensitivity_V_per_Nm: float, **overrides):
    """``bridge.chain.paper_chain`` with strain per N·m scaled to |sensitivity| V per N·m
    (bridge output at zero torque, probed numerically so any bridge arrangement works)."""
    from bridge.chain import paper_chain

    S = abs(sensitivity_V_per_Nm)
    probe_strain = 1e-4
    probe = paper_chain(strain_per_Nm=probe_strain, **overrides)
    dv = float(np.diff(np.asarray(probe.bridge_volts(np.array([0.0, 1e-3]))))[0]) / 1e-3
    return paper_chain(strain_per_Nm=probe_strain * S / abs(dv), **overrides)


def simulate_session(spec: SessionSpec, rng: np.random.Generator) -> Session:
    """Simulate a loading session (vectorized over readings and ADC samples)."""
    levels = np.asarray(spec.masses_g, float)
    order = [levels] + ([levels[::-1][1:]] if spec.unload else [])
    one = np.concatenate(order)
    dirs_one = np.array(["load"] * levels.size + (["unload"] * (levels.size - 1) if spec.unload else []))
    mass_g = np.tile(one, spec.repeats)
    direction = np.tile(dirs_one, spec.repeats)
    repeat = np.repeat(np.arange(spec.repeats), one.size)
    n = mass_g.size
    dwell_s = spec.settle_s + spec.n_avg / spec.sample_rate_Hz
    t_s = np.arange(n) * (dwell_s + 2.0)                       # 2 s to change the weight
    tau = mass_g * 1e-3 * G_STANDARD_M_PER_S2 * spec.lever_arm_m
    step = np.diff(np.concatenate([[0.0], tau]))
    creep = spec.creep_frac * step * (1.0 - np.exp(-spec.settle_s / spec.creep_tau_s))
    reading, chain = sensor_readings(spec, tau, rng, unloading=direction == "unload", t_s=t_s,
                                     extra_Nm=creep, n_avg=spec.n_avg)
    reading = reading + spec.quad_mV_per_g2 * mass_g**2 + rng.normal(0.0, spec.repeat_noise_mV, n)
    L = spec.lever_arm_m
    chain_name = type(chain).__module__ + "." + type(chain).__name__
    return Session(mass_g=mass_g, reading=reading, direction=direction, repeat=repeat,
                   timestamp_s=t_s, lever_arm_m=L, sensor_id=spec.sensor_id, reading_unit="mV",
                   meta={"simulated": f"calibration.simulate via {chain_name}"})


def sensor_readings(spec: SessionSpec, tau_Nm, rng, *, unloading=None, t_s=None, extra_Nm=0.0,
                    n_avg: int = 1):
    """Readings (mV) of the simulated sensor for true torques ``tau_Nm`` (any shape), each the
    mean of ``n_avg`` ADC samples; hysteresis on ``unloading``, temperature drift at ``t_s``.
    Returns (reading_mV, chain). Excludes the dead-weight repeatability noise."""
    tau = np.asarray(tau_Nm, float)
    dT = spec.temp_ramp_C_per_s * (np.zeros_like(tau) if t_s is None else np.asarray(t_s, float))
    unl = np.zeros(tau.shape, bool) if unloading is None else np.asarray(unloading, bool)
    S_V_per_Nm = spec.slope_mV_per_g * 1e-3 / (1e-3 * G_STANDARD_M_PER_S2 * spec.lever_arm_m)
    chain = sensor_chain(S_V_per_Nm, **spec.chain_overrides)
    tau_eff = tau * (1.0 + spec.span_tc_per_C * dT) + spec.hysteresis_Nm * unl + extra_Nm
    samples = np.broadcast_to(tau_eff[..., None], tau.shape + (int(n_avg),))
    tau_meas = np.asarray(chain.torque_from_counts(chain.counts(samples, rng)), float)
    to_volts = getattr(chain, "bridge_volts", chain.volts)     # bridge output, before gain/offset
    v = np.asarray(to_volts(tau_meas), float).mean(axis=-1)
    reading = np.sign(spec.slope_mV_per_g) * 1e3 * v + spec.offset_mV + spec.zero_tc_mV_per_C * dT
    return reading, chain


def chain_noise_mV(spec: SessionSpec) -> float:
    """Standard deviation of one averaged reading due to the chain alone (mV)."""
    S_V_per_Nm = abs(spec.slope_mV_per_g) * 1e-3 / (1e-3 * G_STANDARD_M_PER_S2 * spec.lever_arm_m)
    chain = sensor_chain(S_V_per_Nm, **spec.chain_overrides)
    return float(1e3 * S_V_per_Nm * chain.noise_std_Nm / np.sqrt(spec.n_avg))


def paper_spec(link: int = 1, **changes) -> SessionSpec:
    """Spec at the paper's eq. 12 (link 1) or 13 (link 2), noise set to reproduce its R².

    R² = 1 − σ²/(σ² + s² Var(m)) ⇒ σ² = (1 − R²)/R² · s² Var(m); the repeatability noise is
    what the chain does not already supply: σ_rep² = σ² − σ_chain².
    """
    fit = PAPER_FITS[link]
    spec = SessionSpec(slope_mV_per_g=fit["slope_mV_per_g"], offset_mV=fit["offset_mV"],
                       sensor_id=f"paper-link{link}", **changes)
    var_m = np.var(np.asarray(spec.masses_g, float))
    sigma2 = (1 - fit["r2"]) / fit["r2"] * spec.slope_mV_per_g**2 * var_m
    spec.repeat_noise_mV = float(np.sqrt(max(sigma2 - chain_noise_mV(spec) ** 2, 0.0)))
    return spec


def paper_session(link: int = 1, seed: int = 12, **changes) -> Session:
    """A simulated session at the paper's coefficients (fixed seed → reproducible)."""
    s = simulate_session(paper_spec(link, **changes), np.random.default_rng(seed))
    s.meta["truth"] = (f"slope={PAPER_FITS[link]['slope_mV_per_g']} mV/g, "
                       f"offset={PAPER_FITS[link]['offset_mV']} mV (paper eq. {11 + link})")
    s.meta["seed"] = seed
    return s
