"""Where on the leg a contact can be localized: the Cramér–Rao bound (estimator.bounds) and the
predicted error of our estimator, over postures and force directions.

For each posture q (the leg held, q̇ = 0) and force direction β (|F| given, on the given link and α):

- ``bound_per_sample_m``: the per-sample bound along the link, |Δ_c| √(I⁻¹)_αα, I = Hᵀ R⁻¹ H with
  R the residual covariance of the sensor noise at q (estimator.noise);
- ``bound_episode_m``: the episode bound of a contact held ``hold_s`` (L samples): the long-run
  information L · h ᵀΩ⊥h (estimator.bounds; L + 1 steps after the onset, to 0.2 %);
- ``estimator_rms_m``: a Monte Carlo of the per-sample localizer as the stream runs it (weights
  R⁻¹, its flags: force floor 5σ, 1/sin∠ > 20 → parallel_to_link, ambiguity at 2√n noise norms)
  on r = J(α)ᵀF + n, n ~ N(0, R): the RMS error along the link over the draws it answers, NaN where
  it refuses more than half of them (``refused_fraction``).

The bound grows as 1/|sin∠(F, link)| and diverges where the line of action runs along the link:
there the estimator refuses (parallel_to_link) instead of answering.
"""

from __future__ import annotations

import numpy as np

from estimator import bounds
from estimator import dynamics as dyn
from estimator.localization import localize_dynamic

REFUSE_ABOVE = 0.5          # a map cell is "refused" when the estimator refuses more draws than this


def localization_maps(robot, q_joint, link: int, alpha: float, magnitude_N: float, directions_rad,
                      noise, gain_per_s: float = 100.0, dt_s: float = 1e-3, hold_s: float = 0.5,
                      draws: int = 200, seed: int = 0, max_condition: float = 20.0) -> dict:
    """Arrays (P, D) over postures q_joint (P, N) and force directions (D,) (module doc), plus
    the link's angle to each force (``sin_angle``)."""
    full = robot.with_base(True)
    q_joint = np.atleast_2d(np.asarray(q_joint, float))
    P, N = q_joint.shape
    beta = np.asarray(directions_rad, float)
    D = beta.size
    q = np.concatenate([np.zeros((P, 3)), q_joint], axis=1)
    nt = bounds.noise_terms(full, q, np.zeros_like(q), noise, gain_per_s, dt_s)
    R, Om = nt.R, nt.Omega
    F = magnitude_N * np.stack([np.cos(beta), np.sin(beta)], -1)              # (D, 2)
    qq = np.repeat(q, D, axis=0)                                               # (P·D, n)
    FF = np.tile(F, (P, 1))
    H, length = bounds.design(full, qq, link, alpha, FF)
    Rr, Omr = np.repeat(R, D, axis=0), np.repeat(Om, D, axis=0)
    with np.errstate(all="ignore"):
        ia = bounds.profiled(bounds.fisher(H, Rr))
        ie = bounds.profiled(bounds.fisher(H, Omr))
        L = max(1, int(round(hold_s / dt_s)))
        b_ps = np.where(ia > 0, length / np.sqrt(ia), np.inf)
        b_ep = np.where(ie > 0, length / np.sqrt(L * ie), np.inf)
    joints, _ = dyn.forward_kinematics(full, qq)
    d = joints[:, link] - joints[:, link - 1]
    sin = np.abs(d[:, 0] * FF[:, 1] - d[:, 1] * FF[:, 0]) / np.hypot(*d.T) / magnitude_N
    # the estimator, as the stream runs it, on draws of the residual
    rng = np.random.default_rng(seed)
    J = dyn.point_jacobian(full, qq, link, np.full(P * D, alpha))
    mean = np.einsum("bak,ba->bk", J, FF)                                      # (P·D, n)
    C = np.linalg.cholesky(Rr)
    e = np.einsum("bij,bdj->bdi", C, rng.standard_normal((P * D, draws, q.shape[1])))
    r = (mean[:, None, :] + e).reshape(-1, q.shape[1])
    n = q.shape[1]
    floor = max(0.05, 5.0 * float(np.sqrt(np.max(R[:, :2, :2].diagonal(axis1=1, axis2=2)))))
    W = np.linalg.inv(R)
    widx = np.repeat(np.repeat(np.arange(P), D), draws)
    fit = localize_dynamic(full, np.repeat(qq, draws, axis=0), r, weight=(W, widx),
                           min_force_N=floor, max_condition=max_condition,
                           ambiguity_tol=2.0 * np.sqrt(n))
    a = fit.alpha.reshape(P * D, draws)
    ok = np.isfinite(a) & (fit.link.reshape(P * D, draws) == link)
    refused = 1.0 - ok.mean(axis=1)
    err = np.where(ok, (a - alpha) * length[:, None], 0.0)
    with np.errstate(all="ignore"):
        rms = np.sqrt((err ** 2).sum(axis=1) / ok.sum(axis=1))
    rms = np.where(refused > REFUSE_ABOVE, np.nan, rms)
    shape = (P, D)
    return {"bound_per_sample_m": b_ps.reshape(shape), "bound_episode_m": b_ep.reshape(shape),
            "estimator_rms_m": rms.reshape(shape), "refused_fraction": refused.reshape(shape),
            "sin_angle": sin.reshape(shape), "hold_s": hold_s, "draws": draws}
