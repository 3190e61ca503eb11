"""The scoring of a scene's estimates against its truth: the one definition of the collision phase
and of the errors over it, used by the stages, `demo`, the reports and the reproduction."""

from __future__ import annotations

import numpy as np

METHODS = ("dynamic", "paper")


def collision_phase_mask(t, pokes, gain_per_s: float) -> np.ndarray:
    """The collision phase: t ∈ [t_on + ramp + 5/K, t_off) of each poke (after 5 observer time
    constants the residual is within e⁻⁵ ≈ 0.7 % of the step)."""
    t = np.asarray(t)
    phase = np.zeros(t.shape, bool)
    for p in pokes:
        if p.t_off_s > p.t_on_s:
            phase |= (t >= p.t_on_s + p.ramp_s + 5.0 / gain_per_s) & (t < p.t_off_s)
    return phase


def contact_free_mask(t, pokes, gain_per_s: float) -> np.ndarray:
    """Samples with no contact and no residual of one: outside [t_on, t_off + ramp + 10/K) of
    every poke (10 observer time constants: the residual's decay is below e⁻¹⁰ of the step)."""
    t = np.asarray(t)
    free = np.ones(t.shape, bool)
    for p in pokes:
        free &= ~((t >= p.t_on_s) & (t < p.t_off_s + p.ramp_s + 10.0 / gain_per_s))
    return free


def collision_phase_errors(est, truth, pokes, gain_per_s: float) -> dict:
    """Mean/RMS |p̂ − p| and mean |F̂ − F| over the collision phase (collision_phase_mask), over
    the samples with a finite estimate; the one scoring function of demo, run and the reports."""
    phase = collision_phase_mask(truth["t"], pokes, gain_per_s) & (truth["link"] > 0)
    ok = phase & np.isfinite(est.px)
    dp = np.hypot(est.px[ok] - truth["px"][ok], est.pz[ok] - truth["pz"][ok])
    dF = np.hypot(est.Fx[ok] - truth["Fx"][ok], est.Fz[ok] - truth["Fz"][ok])
    return {"position_error_mean_m": float(dp.mean()) if dp.size else None,
            "position_error_rms_m": float(np.sqrt(np.mean(dp ** 2))) if dp.size else None,
            "force_error_mean_N": float(dF.mean()) if dF.size else None,
            "scored_samples": int(ok.sum()), "collision_samples": int(phase.sum())}

