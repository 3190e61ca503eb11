"""Up-front cost estimate and integration-error estimate of a simulation, from a short probe.

Before the full run, the first window w = min(T, max(10 samples, 2 % of T)) of the scene is
integrated twice: with the scene's settings and with a 10× tighter rtol/atol (adaptive) or a
halved step (RK4).

- cost: wall_time(T) ≈ wall_probe · T / w (rhs evaluations scale the same way); the probe itself
  stops after ``PROBE_RHS_CAP`` evaluations, which already means "hopeless". Explicit adaptive
  methods also have a hard floor: steps ≥ |λ_max| T / c (c ≈ 3.3 for RK45, 6 for DOP853, the
  real-axis extent of their stability regions), whatever the probe saw.
- error: e ≈ max_t∈w |q(settings) − q(tighter)| (rad, joint and base angles/positions). This is an
  estimate of the local integration error over the probe window, not a bound over the whole run.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace

import numpy as np

from userio.errors import InputError
from estimator.sim.config import ADAPTIVE, SimConfig

PROBE_RHS_CAP = 200_000          # rhs evaluations allowed in one probe
PROBE_WALL_CAP_S = 30.0          # and wall time (s): max(1 s, the limit's share w/T of it), at most this
MAX_LOG_SAMPLES = 20_000_000     # (T·fs) rows held in memory by simulate()
EXPLICIT_STABILITY_EXTENT = {"RK45": 3.3, "DOP853": 6.0, "RK4": 2.78}
RHS_PER_STEP = {"RK45": 6, "DOP853": 12, "RK4": 4}


class _Budget(Exception):
    pass


@dataclass(frozen=True)
class CostEstimate:
    window_s: float
    probe_wall_s: float
    probe_rhs_evaluations: int
    predicted_run_time_s: float
    predicted_rhs_evaluations: float
    q_error_estimate: float          # rad / m, max abs difference from the tighter rerun
    error_method: str


def _probe_config(config: SimConfig) -> SimConfig:
    fs = config.sensors.sample_rate_Hz
    w = min(config.duration_s, max(10.0 / fs, 0.02 * config.duration_s))
    w = max(np.floor(w * fs + 1e-9), 1.0) / fs          # whole samples (RK4 needs it)
    pokes = tuple(p for p in config.pokes if p.t_on_s < w)
    return replace(config, duration_s=float(min(w, config.duration_s)), pokes=pokes)


def _run(config: SimConfig, cap: int, wall_cap_s: float = float("inf")):
    """Integrate the probe; _Budget when it needs more than ``cap`` rhs evaluations or more than
    ``wall_cap_s`` of wall time (an implicit method's Newton and LU work between evaluations is
    not counted in the evaluations: the clock bounds it too)."""
    from estimator.sim.integrate import _adaptive, _rk4, sample_times
    from estimator.sim.model import Plant

    plant = Plant(config)
    inner = plant.rhs1
    t_start = time.perf_counter()

    def capped(*a):
        n = getattr(capped, "n", 0)
        if plant.nfev + n > cap or (n % 64 == 0 and time.perf_counter() - t_start > wall_cap_s):
            raise _Budget
        capped.n = n + 1
        return inner(*a)

    plant.rhs1 = capped
    ts = sample_times(config)
    zoh = config.controller.mode == "zoh"
    start = time.perf_counter()
    if config.integrator in ADAPTIVE:
        Y, _ = _adaptive(plant, config, ts, zoh)
    else:
        Y, _ = _rk4(plant, config, ts, zoh)
        Y = Y[:, 0]
    return Y[:, :plant.n], time.perf_counter() - start, plant.nfev + getattr(capped, "n", 0)


def estimate_cost(config: SimConfig, fastest_pole_per_s: float, stiffness_ratio: float,
                  max_run_time_s: float) -> CostEstimate:
    """Probe the first window; refuse (InputError, one line) when the full run cannot finish."""
    T, fs = config.duration_s, config.sensors.sample_rate_Hz
    rows = T * fs
    if not np.isfinite(rows) or rows > MAX_LOG_SAMPLES:
        raise InputError(f"scene '{config.name}': duration_s = {T:g} s at {fs:g} Hz is {rows:.3g} log "
                         f"samples, above the {MAX_LOG_SAMPLES:.0e} an in-memory simulation holds; "
                         f"shorten the duration or lower sensors.sample_rate_Hz")
    m = config.integrator
    if m in EXPLICIT_STABILITY_EXTENT:
        h_stable = EXPLICIT_STABILITY_EXTENT[m] / fastest_pole_per_s
        floor_rhs = T / h_stable * RHS_PER_STEP[m] if m != "RK4" else 0.0
    else:
        floor_rhs = 0.0
    if floor_rhs > 0 and floor_rhs * 2e-5 > max_run_time_s:     # ≥ 20 µs per evaluation
        raise InputError(
            f"scene '{config.name}': explicit {m} needs ≥ {floor_rhs:.3g} right-hand-side evaluations "
            f"(steps ≥ |λ_max|·T/{EXPLICIT_STABILITY_EXTENT[m]:g}, fastest pole {fastest_pole_per_s:.3g} 1/s, "
            f"stiffness ratio {stiffness_ratio:.3g}), over the limit {max_run_time_s:g} s; use Radau or BDF "
            f"(implicit) or raise the limit (--max-run-time)")
    probe = _probe_config(config)
    w = probe.duration_s
    # the probe may spend at most its share of the limit: beyond it the extrapolation is over anyway
    wall_cap = min(PROBE_WALL_CAP_S, max(1.0, max_run_time_s * w / T))
    try:
        q_a, wall, nfev = _run(probe, PROBE_RHS_CAP, wall_cap)
    except _Budget:
        raise InputError(
            f"scene '{config.name}': integrator {m} used up its probe budget ({PROBE_RHS_CAP} "
            f"right-hand-side evaluations or {wall_cap:.3g} s, its share of the limit "
            f"{max_run_time_s:g} s) on the first {w:g} s of {T:g} s (fastest pole "
            f"{fastest_pole_per_s:.3g} 1/s, stiffness ratio {stiffness_ratio:.3g}): the run cannot "
            f"finish; lower the gains/stiffness (controller.kp = {config.controller.kp:g} N·m/rad), "
            f"use Radau/BDF for a stiff scene, or raise --max-run-time") from None
    per_rhs = wall / max(nfev, 1)
    pred_rhs = max(nfev * T / w, floor_rhs)
    pred_s = pred_rhs * per_rhs
    if pred_s > max_run_time_s:
        why = (f" (explicit {m}: steps ≥ |λ_max|·T/{EXPLICIT_STABILITY_EXTENT[m]:g}, fastest pole "
               f"{fastest_pole_per_s:.3g} 1/s, stiffness ratio {stiffness_ratio:.3g}; use Radau or BDF)"
               if floor_rhs >= nfev * T / w else
               f" (fastest pole {fastest_pole_per_s:.3g} 1/s, stiffness ratio {stiffness_ratio:.3g})")
        raise InputError(f"scene '{config.name}': estimated run time {pred_s:.3g} s "
                         f"({pred_rhs:.3g} right-hand-side evaluations at {per_rhs * 1e6:.3g} µs, "
                         f"extrapolated from the first {w:g} s) exceeds the limit {max_run_time_s:g} s"
                         f"{why}; raise the limit (--max-run-time) to run it anyway")
    # error estimate: the same window at 10× tighter tolerances / half the step
    fine = (replace(probe, rtol=probe.rtol / 10, atol=probe.atol / 10) if m in ADAPTIVE
            else replace(probe, fixed_step_s=probe.fixed_step_s / 2))
    try:
        q_b, _, _ = _run(fine, 4 * PROBE_RHS_CAP)
        err = float(np.max(np.abs(q_a - q_b)))
    except _Budget:
        err = float("nan")
    how = (f"difference from a rerun at 10x tighter rtol/atol over the first {w:g} s" if m in ADAPTIVE
           else f"difference from a rerun at half the step (h/2) over the first {w:g} s")
    if m == "RK4" and np.isfinite(err):
        err *= 16.0 / 15.0       # Richardson: e(h) ≈ (y_h − y_{h/2})·2⁴/(2⁴ − 1)
        how += ", Richardson-scaled for order 4"
    return CostEstimate(w, wall, int(nfev), float(pred_s), float(pred_rhs), err,
                        how + " (an estimate, not a bound over the whole run)")


class Watch:
    """Progress and run-time guard during the full integration.

    ``check(t)`` is called every few thousand rhs evaluations: after 2 s of wall time a tqdm bar
    (stderr) shows simulated time; after 5 s, when the extrapolated total elapsed·T/t exceeds
    ``max_run_time_s``, the run is refused (InputError naming the limit) instead of running on.
    """

    def __init__(self, config: SimConfig, max_run_time_s: float, fastest_pole_per_s: float = float("nan"),
                 stiffness_ratio: float = float("nan")):
        self.config, self.limit = config, max_run_time_s
        self.pole, self.ratio = fastest_pole_per_s, stiffness_ratio
        self.start = time.perf_counter()
        self.bar = None

    def check(self, t: float) -> None:
        import sys

        elapsed = time.perf_counter() - self.start
        T = self.config.duration_s
        if elapsed > 2.0 and self.bar is None:
            from tqdm import tqdm
            self.bar = tqdm(total=T, desc=f"simulate {self.config.name}", file=sys.stderr, leave=False,
                            bar_format="{l_bar}{bar}| {n:.3g}/{total:.3g} sim-s [{elapsed}<{remaining}]")
        if self.bar is not None:
            self.bar.n = min(t, T)
            self.bar.refresh()
        if elapsed > 5.0 and (t <= 0 or elapsed * T / t > self.limit):
            self.close()
            predicted = elapsed * T / t if t > 0 else float("inf")
            raise InputError(
                f"scene '{self.config.name}': {self.config.integrator} reached t = {t:.4g} of {T:g} s in "
                f"{elapsed:.3g} s, predicting {predicted:.3g} s > the limit {self.limit:g} s (fastest pole "
                f"{self.pole:.3g} 1/s, stiffness ratio {self.ratio:.3g}); lower the gains/stiffness or "
                f"raise the limit (--max-run-time)")

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()
            self.bar = None
