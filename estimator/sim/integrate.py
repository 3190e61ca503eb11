"""The plant's integration onto the log's sample times: scipy's solve_ivp between the pokes'
on/off instants (and the control ticks of a zero-order hold), or fixed-step classic RK4
vectorized over a batch of initial states (estimator.sim.core runs a scene with them; the cost
probe of estimator.sim.cost times them)."""

from __future__ import annotations

import numpy as np
from scipy.integrate import solve_ivp

from userio.errors import InputError
from estimator.sim.config import SimConfig
from estimator.sim.model import Plant


def sample_times(config: SimConfig) -> np.ndarray:
    fs = config.sensors.sample_rate_Hz
    n = int(np.floor(config.duration_s * fs + 1e-9)) + 1
    return np.arange(n) / fs


def _breakpoints(config: SimConfig) -> np.ndarray:
    pts = {0.0, config.duration_s}
    for p in config.pokes:
        if p.t_off_s <= p.t_on_s:          # a zero-length window applies no force
            continue
        pts.update(b for b in p.breakpoints() if 0.0 < b < config.duration_s)
    return np.array(sorted(pts))


def _adaptive(plant: Plant, config: SimConfig, ts: np.ndarray, zoh: bool, bar=None):
    """solve_ivp between breakpoints (and control ticks for a ZOH); returns states at ts, τ held."""
    cuts = _breakpoints(config)
    if zoh:
        period = 1.0 / config.controller.rate_Hz
        ticks = np.arange(0.0, config.duration_s, period)
        cuts = np.union1d(cuts, ticks)
    y = plant.initial_state(1)[0]
    Y = np.empty((len(ts), plant.n_state))
    held = np.full((len(ts), plant.n_links), np.nan)
    tau_hold = None
    idx = 0
    for a, b in zip(cuts[:-1], cuts[1:]):
        if zoh:
            q, dq, _ = plant.split(y[None, :])
            tau_hold = plant.control(a, q, dq)
        last = b >= config.duration_s - 1e-12
        hi = np.searchsorted(ts, b, side="right" if last else "left")
        t_eval = ts[idx:hi]

        def f(t, yy, _h=tau_hold):
            if bar is not None and plant.nfev % 2000 == 0:
                bar.check(t)
            return plant.rhs1(t, yy, _h)

        grid = np.append(t_eval[t_eval < b], b)
        sol = solve_ivp(f, (a, b), y, method=config.integrator, t_eval=grid,
                        rtol=config.rtol, atol=config.atol)
        if sol.status < 0 or not np.all(np.isfinite(sol.y)):
            raise InputError(f"scene '{config.name}': integrator {config.integrator} failed between "
                             f"t = {a:.6g} and {b:.6g} s: {sol.message}")
        if t_eval.size:
            Y[idx:hi] = sol.y[:, :t_eval.size].T
            if zoh:
                held[idx:hi] = tau_hold
        idx = hi
        y = sol.y[:, -1]
    return Y, held


def _rk4(plant: Plant, config: SimConfig, ts: np.ndarray, zoh: bool, y0=None, bar=None):
    """Classic RK4 with step h (batched over the rows of y0); samples where t hits ts."""
    h = config.fixed_step_s
    per_sample = round(1.0 / (config.sensors.sample_rate_Hz * h))
    if abs(per_sample * h * config.sensors.sample_rate_Hz - 1.0) > 1e-9:
        raise InputError(f"scene '{config.name}': fixed_step_s = {h:g} must divide the sample "
                         f"period 1/{config.sensors.sample_rate_Hz:g} s")
    per_tick = 1
    if zoh:
        per_tick = round(1.0 / (config.controller.rate_Hz * h))
        if per_tick < 1 or abs(per_tick * h * config.controller.rate_Hz - 1.0) > 1e-9:
            raise InputError(f"scene '{config.name}': fixed_step_s = {h:g} must divide the "
                             f"control period 1/{config.controller.rate_Hz:g} s")
    y = plant.initial_state(1) if y0 is None else np.atleast_2d(y0).astype(float)
    Y = np.empty((len(ts),) + y.shape)
    held = np.full((len(ts), y.shape[0], plant.n_links), np.nan)
    n_steps = (len(ts) - 1) * per_sample
    eps = 1e-9 * h
    if y.shape[0] == 1:                       # one state: the plain-float right-hand side
        def rhs(t, yy, hold):
            return plant.rhs1(t, yy[0], hold)[None, :]
    else:
        rhs = plant.rhs
    tau_hold = None
    Y[0] = y
    for k in range(n_steps):
        t = k * h
        if zoh and k % per_tick == 0:
            q, dq, _ = plant.split(y)
            tau_hold = plant.control(t, q, dq)
        if zoh and k % per_sample == 0:
            held[k // per_sample] = tau_hold
        # end stages nudged inside the step by ε so that a force switching on the step grid is
        # seen with its in-step value at every stage (else an O(h) error at each switch)
        k1 = rhs(t + eps, y, tau_hold)
        k2 = rhs(t + h / 2, y + h / 2 * k1, tau_hold)
        k3 = rhs(t + h / 2, y + h / 2 * k2, tau_hold)
        k4 = rhs(t + h - eps, y + h * k3, tau_hold)
        y = y + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        if not np.all(np.isfinite(y)):
            raise InputError(f"scene '{config.name}': RK4 diverged at t = {t:.6g} s")
        if (k + 1) % per_sample == 0:
            Y[(k + 1) // per_sample] = y
            if bar is not None and (k + 1) % (per_sample * 100) == 0:
                bar.check((k + 1) * h)
    if zoh:
        q, dq, _ = plant.split(y)
        held[-1] = tau_hold
    return Y, held
