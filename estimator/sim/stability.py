"""Stability of a (controller, integrator) choice, from the linearized plant at the initial state.

Linearize ẋ = A x + B τ (x = [q, q̇], τ the joint torques, finite differences of the plant with
the PD law removed). With the PD law τ = −K_c x, K_c = [K_P S, K_D S]:

- continuous control: poles λ = eig(A − B K_c); the fastest |λ| sets the stiffness;
- zero-order hold at period h: Φ = e^{Ah}, Γ = ∫_0^h e^{As} ds B (one expm of [[A, B], [0, 0]]),
  closed loop x_{k+1} = (Φ − Γ K_c) x_k, stable iff its spectral radius ρ < 1;
- fixed-step RK4 with step h: stable iff |R(hλ)| ≤ 1 for every pole, R(z) = 1 + z + z²/2 + z³/6 + z⁴/24.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.linalg import expm

from userio.errors import InputError
from estimator.sim.config import SimConfig
from estimator.sim.model import Plant


@dataclass(frozen=True)
class StabilityReport:
    fastest_pole_per_s: float          # max |λ| of the continuous closed loop
    stiffness_ratio: float             # max |Re λ| / min |Re λ| over the nonzero poles
    zoh_spectral_radius: float         # ρ(Φ − Γ K_c) at the configured control rate (nan: continuous)
    min_stable_zoh_rate_Hz: float      # lowest ZOH rate with ρ < 1 (bisection)
    rk4_amplification: float           # max |R(hλ)| at fixed_step_s
    stable: bool
    message: str


def linearize(plant: Plant, eps: float = 1e-7):
    """(A, B, K_c) of the plant at its initial state; ground and bristle states are left out."""
    n, nb, N = plant.n, plant.n_base, plant.n_links
    x0 = plant.initial_state(1)[0, :2 * n]
    extra = plant.initial_state(1)[0, 2 * n:]
    tau0 = np.zeros((1, N))

    def f(x, tau):
        y = np.concatenate([x, extra])[None, :]
        return plant.rhs(0.0, y, tau_hold=tau)[0, :2 * n]

    base = f(x0, tau0)
    A = np.empty((2 * n, 2 * n))
    for j in range(2 * n):
        dx = np.zeros(2 * n)
        dx[j] = eps * max(1.0, abs(x0[j]))
        A[:, j] = (f(x0 + dx, tau0) - f(x0 - dx, tau0)) / (2 * dx[j])
    B = np.empty((2 * n, N))
    for j in range(N):
        dt = np.zeros((1, N))
        dt[0, j] = 1e-3
        B[:, j] = (f(x0, tau0 + dt) - base) / 1e-3
    S = np.zeros((N, n))
    S[np.arange(N), nb + np.arange(N)] = 1.0
    K_c = np.hstack([plant.kp * S, plant.kd * S])
    return A, B, K_c


def zoh_matrices(A, B, h):
    """Φ = e^{Ah}, Γ = ∫_0^h e^{As} ds B."""
    m, k = B.shape
    aug = np.zeros((m + k, m + k))
    aug[:m, :m], aug[:m, m:] = A, B
    E = expm(aug * h)
    return E[:m, :m], E[:m, m:]


def zoh_radius(A, B, K_c, rate_Hz: float) -> float:
    Phi, Gam = zoh_matrices(A, B, 1.0 / rate_Hz)
    return float(np.max(np.abs(np.linalg.eigvals(Phi - Gam @ K_c))))


def rk4_amplification(poles, h) -> float:
    """max |R(hλ)| over the decaying poles (Re λ < 0; growing ones grow in the ODE too)."""
    poles = np.asarray(poles)
    poles = poles[poles.real < 0]
    if poles.size == 0:
        return 0.0
    z = poles * h
    return float(np.max(np.abs(1 + z + z**2 / 2 + z**3 / 6 + z**4 / 24)))


def check_stability(config: SimConfig, *, raise_on_unstable: bool = False) -> StabilityReport:
    """Report (and optionally refuse) an unstable controller/integrator combination."""
    plant = Plant(config)
    A, B, K_c = linearize(plant)
    poles = np.linalg.eigvals(A - B @ K_c)
    fastest = float(np.max(np.abs(poles)))
    re = np.abs(poles.real[np.abs(poles.real) > 1e-9])
    ratio = float(re.max() / re.min()) if re.size else 1.0
    ctrl = config.controller
    # lowest stable ZOH rate (ρ decreases with rate once past the fastest pole; bisection in log f)
    lo, hi = 10.0, 1e7
    if zoh_radius(A, B, K_c, hi) >= 1.0:
        min_rate = float("nan")
    else:
        for _ in range(40):
            mid = np.sqrt(lo * hi)
            lo, hi = (mid, hi) if zoh_radius(A, B, K_c, mid) >= 1.0 else (lo, mid)
        min_rate = hi
    rho = zoh_radius(A, B, K_c, ctrl.rate_Hz) if ctrl.mode == "zoh" else float("nan")
    h = config.fixed_step_s
    if config.integrator == "RK4":
        open_poles = np.linalg.eigvals(A)
        amp = rk4_amplification(poles if ctrl.mode == "continuous" else open_poles, h)
        if ctrl.mode == "zoh":    # the held-torque plant between ticks, stepped at h
            amp = max(amp, rk4_amplification(open_poles, h))
    else:
        amp = float("nan")
    problems = []
    if ctrl.mode == "zoh" and rho >= 1.0:
        problems.append(
            f"zero-order-hold PD at {ctrl.rate_Hz:g} Hz (K_P={ctrl.kp:g}, K_D={ctrl.kd:g}) is unstable: "
            f"discrete closed-loop spectral radius {rho:.3g} ≥ 1 (fastest continuous pole "
            f"{fastest:.3g} 1/s); use controller.mode = \"continuous\" or a rate ≥ {min_rate:.4g} Hz")
    if config.integrator == "RK4" and amp > 1.0 + 1e-9:
        problems.append(
            f"fixed-step RK4 with h = {h:g} s is unstable for this scene: |R(hλ)| = {amp:.3g} > 1 "
            f"(fastest pole {fastest:.3g} 1/s needs h < {2.78 / fastest:.3g} s); use a smaller "
            f"fixed_step_s or Radau/BDF")
    message = "; ".join(problems) if problems else (
        f"stable: fastest pole {fastest:.3g} 1/s, stiffness ratio {ratio:.3g}")
    report = StabilityReport(fastest, ratio, rho, min_rate, amp, not problems, message)
    if problems and raise_on_unstable:
        raise InputError(f"scene '{config.name}': " + message)
    return report
