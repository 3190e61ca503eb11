"""Run a scene: integrate the plant, sample it at the log rate, apply the sensor models.

Integrators: scipy.integrate.solve_ivp ("RK45" = MATLAB's ode45 pair, "DOP853", "Radau", "BDF",
"LSODA"), integrated piecewise between the pokes' on/off instants (no step straddles a force
discontinuity); and a fixed-step classic RK4 ("RK4", step ``fixed_step_s``) that is vectorized
over a batch of initial states. Control is continuous (τ evaluated at every stage) or a zero-order
hold at ``controller.rate_Hz`` (τ computed at each tick and held). Unstable combinations are
refused before integrating (see stability.check_stability).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from estimator import dynamics as dyn
from userio.errors import InputError
from estimator.log import SensorLog
from estimator.sim.cost import Watch, estimate_cost
from estimator.sim.integrate import _adaptive, _rk4, sample_times
from estimator.sim.config import ADAPTIVE, INTEGRATORS, SimConfig
from estimator.sim.model import Plant
from estimator.sim.sensors import measure
from estimator.sim.stability import check_stability


@dataclass
class SimResult:
    """Sampled truth and measured log. Arrays are per log sample (T,)."""

    config: SimConfig
    t: np.ndarray
    q: np.ndarray                 # (T, N+3) true coordinates, floating layout (zero base if welded)
    dq: np.ndarray
    tau_Nm: np.ndarray            # (T, N) true joint torques (what the servo applies)
    wrench: np.ndarray            # (T, 3) true mount wrench on the base
    ground_force_N: np.ndarray    # (T, 2) foot–ground force (zeros without ground)
    log: SensorLog                # measured
    truth: dict                   # t, link, alpha, Fx, Fz, px, pz
    stats: dict = field(default_factory=dict)


def truth_table(config: SimConfig, ts: np.ndarray, q: np.ndarray) -> dict:
    """Per sample the applied poke (link 0 and NaN when none): t, link, alpha, Fx, Fz, px, pz."""
    T = len(ts)
    out = {"t": ts, "link": np.zeros(T, dtype=int), "alpha": np.full(T, np.nan),
           "Fx": np.zeros(T), "Fz": np.zeros(T), "px": np.full(T, np.nan), "pz": np.full(T, np.nan)}
    best = np.zeros(T)
    for p in config.pokes:
        s = p.profile(ts)
        take = (s > 0) & (s * p.magnitude_N > best)
        if not np.any(take):
            continue
        best = np.where(take, s * p.magnitude_N, best)
        F = s[:, None] * p.force_N
        point = dyn.contact_point(config.robot.with_base(True), q[take], p.link, p.alpha)
        out["link"][take] = p.link
        out["alpha"][take] = p.alpha
        out["Fx"][take], out["Fz"][take] = F[take, 0], F[take, 1]
        out["px"][take], out["pz"][take] = point[:, 0], point[:, 1]
    return out


def simulate(config: SimConfig, *, check: bool = True, max_run_time_s: float = 600.0,
             estimate: bool = True) -> SimResult:
    """Integrate ``config`` and return the sampled truth and the measured log.

    With ``estimate`` (default) a short probe first predicts the run time (refused above
    ``max_run_time_s``) and estimates the integration error (see estimator.sim.cost); a run
    still running after 2 s shows a tqdm bar on stderr, and one extrapolated past the limit after
    5 s is stopped with an InputError (see estimator.sim.cost.Watch).
    """
    if config.integrator not in INTEGRATORS:
        raise InputError(f"scene '{config.name}': integrator must be one of {', '.join(INTEGRATORS)}, "
                         f"got {config.integrator!r}")
    if config.base == "rigid" and config.ground is not None:
        raise InputError(f"scene '{config.name}': a ground contact needs a floating or spring-mounted base")
    if not (np.isfinite(config.duration_s) and config.duration_s > 0):
        raise InputError(f"scene '{config.name}': duration_s must be a finite number > 0, "
                         f"got {config.duration_s!r}")
    stab = check_stability(config, raise_on_unstable=check)
    cost = (estimate_cost(config, stab.fastest_pole_per_s, stab.stiffness_ratio, max_run_time_s)
            if estimate else None)
    plant = Plant(config)
    ts = sample_times(config)
    zoh = config.controller.mode == "zoh"
    bar = Watch(config, max_run_time_s, stab.fastest_pole_per_s, stab.stiffness_ratio)
    start = time.perf_counter()
    try:
        if config.integrator in ADAPTIVE:
            Y, held = _adaptive(plant, config, ts, zoh, bar)
        else:
            Y, held = _rk4(plant, config, ts, zoh, bar=bar)
            Y, held = Y[:, 0], held[:, 0]
    finally:
        bar.close()
    wall = time.perf_counter() - start
    q, dq, s = plant.split(Y)
    tau = held if zoh else plant.control(ts, q, dq)
    if plant.rigid:
        wrench = plant.constraint_wrench(ts, q, dq, tau)
        zeros = np.zeros((len(ts), 3))
        q, dq = np.concatenate([zeros, q], 1), np.concatenate([zeros, dq], 1)
    else:
        wrench = plant.mount_wrench(q, dq)
    ground = plant.external(ts, q, dq, s)[1] if plant.has_ground else np.zeros((len(ts), 2))
    truth = truth_table(config, ts, q)
    n_base_log = 3 if config.base == "floating" else 0
    qm, dqm, taum, Wm = measure(config.sensors, q, dq, tau, wrench, 3)
    if n_base_log == 0:   # fixed / rigid: the log has no base columns (zero base, docs/conventions.md)
        qm[:, :3] = 0.0
        dqm[:, :3] = 0.0
    log = SensorLog(t=ts, q=qm, dq=dqm, tau_Nm=taum, wrench=Wm, floating=config.base == "floating")
    stats = {"integrator": config.integrator, "control": config.controller.mode,
             "run_time_s": wall, "rhs_evaluations": plant.nfev,
             "real_time_factor": config.duration_s / wall if wall > 0 else float("inf"),
             "fastest_pole_per_s": stab.fastest_pole_per_s,
             "min_stable_zoh_rate_Hz": stab.min_stable_zoh_rate_Hz, "stability": stab.message,
             "stiffness_ratio": stab.stiffness_ratio}
    if cost is not None:
        stats.update({"predicted_run_time_s": cost.predicted_run_time_s,
                      "q_rad_error_estimate": cost.q_error_estimate,
                      "q_rad_error_method": cost.error_method})
    return SimResult(config, ts, q, dq, tau, wrench, ground, log, truth, stats)


def simulate_batch(config: SimConfig, initial_states: np.ndarray, *, check: bool = True):
    """Fixed-step RK4 over a batch of initial states sharing one scene (vectorized right-hand side).

    ``initial_states`` (B, n_state) as from ``Plant(config).initial_state(B)`` (perturbed);
    returns (t (T,), states (T, B, n_state)). The scene's integrator must be "RK4".
    """
    if config.integrator != "RK4":
        raise InputError(f"scene '{config.name}': simulate_batch integrates with RK4, "
                         f"got integrator {config.integrator!r}")
    check_stability(config, raise_on_unstable=check)
    plant = Plant(config)
    y0 = np.atleast_2d(np.asarray(initial_states, float))
    if y0.shape[1] != plant.n_state:
        raise InputError(f"scene '{config.name}': initial states need {plant.n_state} columns, "
                         f"got {y0.shape[1]}")
    ts = sample_times(config)
    Y, _ = _rk4(plant, config, ts, config.controller.mode == "zoh", y0=y0)
    return ts, Y
