"""What the estimator stream adds to each contact interval: the episode's maximum-likelihood point
with its honest ± (estimator.episode), the Cramér–Rao bounds beside it (estimator.bounds), and
splits where a contact slides. ``EpisodeStage`` is the stream's hook: ``feed`` after each part's
localization, ``fields`` for each closed interval.

Noise. The per-sample bound uses the detector's covariance R (whatever it holds: the sensor noise
model, a quiet window's robust estimate, model terms) and, for the samples right after an onset,
the covariance of the restarted residual (estimator.onset). The episode uses the drive's
lag-zero/lag-one covariances S0, S1 and long-run Ω: from the sensor noise model at the detector's
posture blocks, or estimated on the quiet window (estimator.bounds.sample_terms).
"""

from __future__ import annotations

import numpy as np

from estimator import bounds, episode, onset
from estimator.episode_tracker import EpisodeTracker

EPISODE_METHOD = ("maximum likelihood over the episode's samples (one contact point, the force "
                  "free per sample, the observer's drive whitened by its long-run covariance), "
                  "sandwich covariance with the residual's serial correlation, 1σ")


class EpisodeStage:
    """Per stream: the episode tracker and the noise terms of the posture blocks."""

    def __init__(self, robot, K, dt_s: float, noise=None, gain_per_s=100.0, timing=None,
                 drive: bounds.ResidualNoise | None = None, position_tol_m: float = 0.005):
        self.robot = robot if robot.floating else robot.with_base(True)
        self.N = robot.n_links
        self.K = np.asarray(K, float)
        self.dt = float(dt_s)
        self.noise, self.gain, self.timing = noise, gain_per_s, timing
        self.drive = drive                     # fixed (quiet window) or None: from the noise model
        self.tracker = EpisodeTracker(robot, K, position_tol_m)
        self._cache = {}                       # block posture bytes → ResidualNoise

    # ---------------------------------------------------------------- noise per block
    def terms(self, rec) -> bounds.ResidualNoise:
        """The part's ResidualNoise per covariance block (computed once per part)."""
        if rec.get("drive") is None:
            rec["drive"] = self._terms(rec["Linv"][0], rec.get("post"))
        return rec["drive"]

    def _terms(self, Linv, post):
        """ResidualNoise per block (B, n, n) with R the detector's (R = (L⁻ᵀ L⁻¹)⁻¹)."""
        R = np.linalg.inv(np.einsum("bki,bkj->bij", Linv, Linv))
        if self.drive is not None:
            d = self.drive
            return bounds.ResidualNoise(R, np.broadcast_to(d.S0[0], R.shape), np.broadcast_to(d.S1[0], R.shape),
                                        d.a, d.b)
        qb, dqb = post
        out = []
        for i in range(len(qb)):
            key = qb[i].tobytes() + dqb[i].tobytes()
            if key not in self._cache:
                if len(self._cache) > 64:
                    self._cache.clear()
                self._cache[key] = bounds.noise_terms(self.robot, qb[i:i + 1], dqb[i:i + 1], self.noise,
                                                      self.gain, self.dt, self.timing)
            out.append(self._cache[key])
        S0 = np.concatenate([o.S0 for o in out])
        S1 = np.concatenate([o.S1 for o in out])
        return bounds.ResidualNoise(R, S0, S1, out[0].a, out[0].b)

    # ---------------------------------------------------------------- per part
    def feed(self, rec, t, q, r_obs, contact, link, alpha, force, q_loc, since_s):
        """After a part's localization: the per-sample bounds, the tracker; returns ``breaks``."""
        idx = rec["Linv"][1]
        nt = self.terms(rec)
        T = len(t)
        bound2 = np.full(T, np.nan)
        ok = np.flatnonzero(np.isfinite(alpha) & contact)
        if ok.size:
            # Cov r̃ after j steps from the onset restart: R once a^(2j) is negligible, so the
            # inverses are needed for the (block, j) pairs with j ≤ j_max only
            j_max = int(np.ceil(np.log(1e-9) / (2 * np.log(np.max(nt.a)))))
            j = np.minimum(np.rint(since_s[ok] / self.dt), j_max).astype(int)
            key = idx[ok] * (j_max + 1) + j
            uniq, inv = np.unique(key, return_inverse=True)
            Rt = onset.restarted_covariance(nt.R[uniq // (j_max + 1)], nt.G1[uniq // (j_max + 1)], nt.a,
                                            uniq % (j_max + 1))
            with np.errstate(all="ignore"):
                Rinv = np.linalg.inv(np.where((uniq % (j_max + 1) > 0)[:, None, None], Rt,
                                              np.eye(len(nt.a))))
            b2 = bounds.per_sample_alpha_var(self.robot, q_loc[ok], link[ok], alpha[ok], force[ok],
                                             Rinv, inv)
            bound2[ok] = np.where(j > 0, b2, np.nan)
        W = np.linalg.inv(nt.Omega)
        return self.tracker.feed(t, r_obs, q, contact, link, bound2, (W, nt.S0, nt.S1, idx))

    def finish(self):
        self.tracker.finish()

    # ---------------------------------------------------------------- per interval
    def fields(self, link: int, well_conditioned: bool) -> dict:
        """The next closed episode's fields on ``link`` (the interval's most frequent one):
        α, p, their 1σ, the bounds and the ratio; NaN with a reason where it is refused."""
        sums = self.tracker.closed.pop(0)
        lay = self.tracker.lay
        res = episode.solve(lay, sums, link)
        nan = float("nan")
        out = {"alpha": nan, "px_m": nan, "pz_m": nan, "episode_reason": res["reason"],
               "episode_samples": int(sums[lay.samples])}
        length = res["length_m"]
        bound_ps = res["alpha_bound_per_sample"]
        out["alpha_bound_per_sample"] = _num(bound_ps)
        out["position_bound_per_sample_m"] = _num(bound_ps * length)
        if res["reason"] == "ok" and not well_conditioned:
            res["reason"] = "no well-conditioned sample"
        if res["reason"] != "ok":
            out["episode_reason"] = res["reason"]
            for key in ("alpha", "px_m", "pz_m"):
                out[f"{key}_error_estimate"] = None
                out[f"{key}_error_method"] = f"not available: the episode estimate is refused ({res['reason']})"
            out.update(alpha_bound=_num(res["alpha_bound"]), position_bound_m=_num(res["alpha_bound"] * length),
                       position_m_error_estimate=None, error_over_bound=None)
            return out
        a = float(np.clip(res["alpha"], 0.0, 1.0))
        p = res["p0"] + a * res["dl"]
        s = res["alpha_std"]
        out.update(alpha=a, px_m=float(p[0]), pz_m=float(p[1]),
                   alpha_error_estimate=s, alpha_error_method=EPISODE_METHOD,
                   px_m_error_estimate=float(abs(res["dl"][0]) * s), px_m_error_method=EPISODE_METHOD,
                   pz_m_error_estimate=float(abs(res["dl"][1]) * s), pz_m_error_method=EPISODE_METHOD,
                   position_m_error_estimate=float(s * length),
                   alpha_bound=res["alpha_bound"], position_bound_m=float(res["alpha_bound"] * length),
                   error_over_bound=float(s / res["alpha_bound"]))
        return out


def _num(v):
    v = float(v)
    return v if np.isfinite(v) else None
