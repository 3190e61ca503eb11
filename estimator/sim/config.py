"""Simulation configuration: what a scene file describes once validated.

Units are SI; angles follow docs/conventions.md (from the downward vertical, counterclockwise-positive).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from estimator.limits import ALPHA_RANGE, FORCE_RANGE, SAMPLE_RATE_RANGE
from estimator.robot import Robot
from userio.ranges import Range, ranged

TWO_PI = 2 * math.pi
ANGLE_RANGE = Range(-TWO_PI, TWO_PI, "rad", low="degrees typed as rad?", high="degrees typed as rad?")
TIME_RANGE = Range(0.0, 1e6, "s", high="a simulated run of more than 11 days")

INTEGRATORS = ("RK45", "DOP853", "Radau", "BDF", "LSODA", "RK4")
ADAPTIVE = ("RK45", "DOP853", "Radau", "BDF", "LSODA")
FIXED_STIFF_MOUNT = (np.array([1e6, 1e6, 1e4]), np.array([1e3, 1e3, 10.0]))
"""Default spring-damper emulating a rigid FT mount (x, z, θ): ω ≈ 925 and 756 rad/s, ζ ≈ 0.4."""


@dataclass(frozen=True)
class Poke:
    """A point force F(t) = magnitude · s(t) · (cos β, sin β) on (link, α), β = direction_rad.

    s(t) rises linearly from 0 at t_on_s to 1 at t_on_s + ramp_s, and falls from 1 at t_off_s to
    0 at t_off_s + ramp_s (ramp_s = 0: steps). t_on_s = t_off_s is a window of zero length.
    """

    link: int
    alpha: float = ranged(0.5, ALPHA_RANGE)
    magnitude_N: float = ranged(0.0, FORCE_RANGE)
    direction_rad: float = 0.0
    t_on_s: float = ranged(0.0, TIME_RANGE)
    t_off_s: float = ranged(0.0, TIME_RANGE)
    ramp_s: float = ranged(0.0, Range(0.0, 100.0, "s"))

    @property
    def force_N(self) -> np.ndarray:
        return self.magnitude_N * np.array([math.cos(self.direction_rad), math.sin(self.direction_rad)])

    def profile(self, t) -> np.ndarray:
        """s(t) ∈ [0, 1], vectorized over t."""
        t = np.asarray(t, dtype=float)
        if self.t_off_s <= self.t_on_s:
            return np.zeros_like(t)
        if self.ramp_s > 0:
            up = np.clip((t - self.t_on_s) / self.ramp_s, 0.0, 1.0)
            down = np.clip(1.0 - (t - self.t_off_s) / self.ramp_s, 0.0, 1.0)
            return np.minimum(up, down)
        return ((t >= self.t_on_s) & (t < self.t_off_s)).astype(float)

    def breakpoints(self) -> list[float]:
        return [self.t_on_s, self.t_on_s + self.ramp_s, self.t_off_s, self.t_off_s + self.ramp_s]


@dataclass(frozen=True)
class Controller:
    """Joint PD: τ = K_P (q_d(t) − q) + K_D (q̇_d(t) − q̇) [+ G_joint(q)].

    q_d(t) = q0 + Σ_h A_h sin(2π f_h t + φ_h) per joint (A = 0: hold q0): one sine per joint
    (amplitude, frequency, phase of shape (N,)) or several harmonics (shape (N, H): a Fourier
    excitation trajectory). ``mode`` "continuous" evaluates τ at every integrator stage; "zoh"
    holds it over 1/rate_Hz.
    """

    q0_rad: np.ndarray = field(metadata={"range": ANGLE_RANGE})
    kp: float = ranged(500.0, Range(0.0, 1e7, "N·m/rad", high="no joint servo is this stiff"))
    kd: float = ranged(10.0, Range(0.0, 1e5, "N·m·s/rad", high="no joint servo damps this hard"))
    mode: str = "continuous"
    rate_Hz: float = ranged(1000.0, Range(1.0, 1e6, "Hz"))
    amplitude_rad: np.ndarray | None = ranged(None, Range(-math.pi, math.pi, "rad",
                                                          low="degrees typed as rad?",
                                                          high="degrees typed as rad?"))
    frequency_Hz: np.ndarray | None = ranged(None, Range(0.0, 100.0, "Hz", high="a leg's reference "
                                                         "trajectory swings at a few Hz; rad/s "
                                                         "typed as Hz?"))
    phase_rad: np.ndarray | None = None
    gravity_compensation: bool = False

    def reference(self, t):
        """(q_d, q̇_d) at times t: shapes (..., N)."""
        t = np.asarray(t, dtype=float)[..., None]
        q0 = np.asarray(self.q0_rad, float)
        if self.amplitude_rad is None:
            return np.broadcast_to(q0, t.shape[:-1] + q0.shape), np.zeros(t.shape[:-1] + q0.shape)
        a, f, ph = self.harmonics()
        w = 2 * np.pi * f
        arg = w * t[..., None] + ph                                   # (..., N, H)
        return q0 + np.sum(a * np.sin(arg), axis=-1), np.sum(a * w * np.cos(arg), axis=-1)

    def harmonics(self):
        """(A, f, φ) as (N, H) arrays (one column for a single sine per joint)."""
        a, f, ph = (np.asarray(x, float) for x in (self.amplitude_rad, self.frequency_Hz,
                                                    self.phase_rad))
        if a.ndim == 1:
            a, f, ph = a[:, None], f[:, None], ph[:, None]
        return a, f, ph


@dataclass(frozen=True)
class Ground:
    """Foot (last link, α = 1) on a flat floor z = height_m.

    Normal: F_n = max(0, k δ − d ż), δ = height − z_foot > 0. Tangential: a bristle (Dahl-type)
    state s with ṡ = v_t (1 − sgn(v_t) s / s_max), s_max = μ F_n / k_t, F_t = −k_t s, so
    |F_t| ≤ μ F_n: the foot sticks (F_t elastic) until the bristle saturates, then slips at μ F_n.
    """

    height_m: float = ranged(0.0, Range(-10.0, 10.0, "m", high="mm typed as m?", low="mm typed as m?"))
    stiffness_N_per_m: float = ranged(2e4, Range(1.0, 1e9, "N/m"))
    damping_Ns_per_m: float = ranged(200.0, Range(0.0, 1e7, "N·s/m"))
    tangential_stiffness_N_per_m: float = ranged(2e4, Range(1.0, 1e9, "N/m"))
    friction_coefficient: float = ranged(0.3, Range(0.0, 10.0, ""))


@dataclass(frozen=True)
class Sensors:
    """Sensor models applied to the sampled truth.

    torque: "gaussian" (σ = torque_noise_Nm) or "bridge" (bridge.chain.paper_chain(), read
    through the bridge/ADC chain); FT: Gaussian σ_FT per axis; encoders: quantization to
    2π/encoder_counts (0 = off); sample_rate_Hz of the log.
    """

    sample_rate_Hz: float = ranged(1000.0, SAMPLE_RATE_RANGE)
    torque_model: str = "gaussian"
    torque_noise_Nm: float = ranged(0.01, Range(1e-12, 1e4, "N·m", zero_ok=True, low="0 for a noise-free "
                                                "sensor; no torque sensor is quieter than 1 pN·m",
                                                high="N·mm typed as N·m?"))
    ft_noise: np.ndarray = ranged([0.1, 0.1, 0.01], Range(1e-9, 1e5, "N or N·m", zero_ok=True,
                                                           low="0 for a noise-free sensor; no FT sensor is "
                                                               "quieter than 1 nN", high="mN typed as N?"))
    encoder_counts: int = ranged(0, Range(4, 2.0 ** 40, "counts/rev", zero_ok=True))
    velocity_noise_rad_per_s: float = ranged(0.0, Range(0.0, 1e3, "rad/s", high="deg/s typed as rad/s?"))
    seed: int = 0


@dataclass(frozen=True)
class SimConfig:
    """One simulation. ``robot`` carries the mass data and, for a floating base, the mount springs.

    base: "floating" (Table II springs, logged with x, z, θ), "fixed" (a stiff spring-damper mount
    emulating the FT sensor, as the paper did, logged without base columns) or "rigid" (welded;
    the FT reading is the exact constraint wrench).
    """

    robot: Robot
    controller: Controller
    base: str = "floating"
    duration_s: float = ranged(1.5, Range(0.0, 1e6, "s", lo_open=True, high="more than 11 days"))
    pokes: tuple[Poke, ...] = ()
    ground: Ground | None = None
    sensors: Sensors = field(default_factory=Sensors)
    integrator: str = "BDF"       # stiff-capable, fastest here (see reports/paper_reproduction.md)
    rtol: float = 1e-6
    atol: float = 1e-8
    fixed_step_s: float = ranged(5e-5, Range(1e-9, 1.0, "s", lo_open=True))
    mount_stiffness: np.ndarray | None = ranged(None, Range(0.0, 1e12, "N/m or N·m/rad"))
    mount_damping: np.ndarray | None = ranged(None, Range(0.0, 1e9, "N·s/m or N·m·s/rad"))
    name: str = "scene"

    def mount(self) -> tuple[np.ndarray, np.ndarray]:
        """(K_b, D_b) of the base mount in (x, z, θ)."""
        if self.mount_stiffness is not None:
            return np.asarray(self.mount_stiffness, float), np.asarray(self.mount_damping, float)
        if self.base == "fixed":
            return FIXED_STIFF_MOUNT
        return np.asarray(self.robot.base_stiffness, float), np.asarray(self.robot.base_damping, float)
