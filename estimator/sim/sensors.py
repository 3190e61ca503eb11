"""Sensor models applied to the sampled truth: joint torque, FT wrench, encoders.

torque: τ_meas = τ + N(0, σ_τ²) ("gaussian"), or read through a bridge.chain.SensorChain ("bridge":
torque → strain → bridge volts → ADC counts → torque, with its own noise and quantization): the
``chain`` given to :func:`measure` (the one sensor model of torquebench.pipeline, e.g. a flexure's
strain per N·m), else the paper's ``paper_chain()``.
FT: W_meas = W + N(0, diag σ_FT²). Encoders: q_meas = Δ round(q / Δ), Δ = 2π / counts.
"""

from __future__ import annotations

import numpy as np

from userio.errors import InputError
from estimator.sim.config import Sensors


def bridge_chain():
    """The paper's bridge/ADC chain, or None when the bridge package does not provide it yet."""
    try:
        from bridge.chain import paper_chain
    except ImportError:
        return None
    return paper_chain()


def measure(sensors: Sensors, q, dq, tau_Nm, wrench, n_base: int, chain=None):
    """Noisy, quantized readings (q, q̇, τ, W) of the true sampled signals (arrays (T, ·)).

    ``chain``: the torque sensor's SensorChain for ``torque_model = "bridge"`` (default: paper's)."""
    rng = np.random.default_rng(sensors.seed)
    q = np.array(q, dtype=float, copy=True)
    dq = np.array(dq, dtype=float, copy=True)
    if sensors.encoder_counts > 0:
        step = 2 * np.pi / sensors.encoder_counts
        q[:, n_base:] = np.round(q[:, n_base:] / step) * step
    if sensors.velocity_noise_rad_per_s > 0:
        dq[:, n_base:] += rng.normal(0.0, sensors.velocity_noise_rad_per_s, dq[:, n_base:].shape)
    if sensors.torque_model == "bridge":
        chain = chain if chain is not None else bridge_chain()
        if chain is None:
            raise InputError("sensors.torque_model: 'bridge' needs bridge.chain.paper_chain, "
                             "which this installation does not provide; use 'gaussian'")
        tau = np.asarray(chain.measure(np.asarray(tau_Nm, float), rng), dtype=float)
    elif sensors.torque_noise_Nm > 0:
        tau = tau_Nm + rng.normal(0.0, sensors.torque_noise_Nm, np.shape(tau_Nm))
    else:
        tau = np.array(tau_Nm, dtype=float, copy=True)
    ft = np.asarray(sensors.ft_noise, float)
    W = wrench + rng.normal(0.0, 1.0, np.shape(wrench)) * ft
    return q, dq, tau, W
