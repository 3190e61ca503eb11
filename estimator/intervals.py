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
from estimator.interval_runs import IntervalRuns

EPISODE_METHOD = ("maximum likelihood over the episode's samples (one contact point, the force "
                  "free per sample, the observer's drive whitened by its long-run covariance), "
                  "sandwich covariance with the residual's serial correlation, 1σ")


#: the observer's rise left out of an interval's mean force: samples within RISE_TIME_CONSTANTS
#: of the slowest row's 1/K after the run's restart (estimator.onset)
RISE_TIME_CONSTANTS = 3.0
FORCE_METHOD = ("mean over the interval's steady samples (from {rise:.3g} s = {n:g}/K after its onset, the "
                "observer's rise left out) of the per-sample force, rise-corrected: F̄ = Σ F_k / Σ (1 − e^(−K t_k)), "
                "t_k the time since the restart (exact for a held force); 1σ = σ_k · min(√(ρ n), n) / Σ c_k, σ_k "
                "the per-sample 1σ, n the samples, ρ = λ_max(R⁻¹Ω) the residual's long-run over its per-sample "
                "covariance (a bound, exact for white sensor noise)")


class SteadyForce(IntervalRuns):
    """An interval's mean force from its steady samples, in bounded memory across chunks.

    The localization reads the observer restarted at the run's first flagged sample s
    (estimator.onset): r̃_k = Σ_{i=s}^{k−1} A^(k−1−i) b d_i, so a force F held from before s reads
    E[F_k] = (1 − a^(k−s)) F with a = e^(−KΔt). The plain mean of F_k over an interval of L samples
    is thus low by about F·(1/(1 − a))/L (10 % of F for a 100 ms contact at K = 100 /s), a bias its
    per-sample ± does not cover. Here the samples within RISE_TIME_CONSTANTS/K of s are left out and
    the rest weighted by their rise factor c_k = 1 − e^(−K t_k):

        F̄ = Σ_steady F_k / Σ_steady c_k        (E[F̄] = F for a held force)

    Its 1σ: F_k's noise is the residual's (lag-zero covariance R, long-run Ω = the drive's, since the
    observer's filter has unit gain at zero frequency) through the fit, so Var Σ F_k ≈ n P Ω Pᵀ ≤
    n ρ P R Pᵀ = n ρ σ_k², ρ = λ_max(R⁻¹Ω) (≈ (1 + a)/(1 − a) = 21 at K = 100 /s, 1 kHz for white
    sensor noise), and never above n² σ_k² (fully correlated): σ(F̄) = σ_k min(√(ρ n), n) / Σ c_k.

    (an interval without steady samples, shorter than the rise, uses all its samples the same way).
    Intervals are the contact runs split at ``breaks`` (slides): estimator.interval_runs, the
    base it shares with the interval accumulator of estimator.interval_summary (same intervals,
    closed in the same order). K: the slowest row's gain (the correction is
    exact when all rows share K, as the default observer's)."""

    KEYS = ("Fx", "Fz", "c", "n", "Fx_all", "Fz_all", "c_all", "n_all")

    def __init__(self, n_links: int, gain_per_s):
        super().__init__(n_links)
        self.K = float(np.min(gain_per_s))
        self.rise_s = RISE_TIME_CONSTANTS / self.K

    def _new(self):
        return np.zeros((len(self.KEYS) + 1, self.nb))      # the last row: ρ (max over the interval)

    def feed(self, contact, link, force, since_s, breaks=None, rho: float = 1.0):
        """One part's samples: flags, per-sample link and force (T, 2), time since the restart
        (s), the tracker's ``breaks`` and ρ = λ_max(R⁻¹Ω) of the part's noise blocks."""
        starts, stops, continued, sid = self.runs(contact, breaks)
        if not starts.size:
            return
        c = np.asarray(contact, bool)
        F = np.asarray(force, float)
        since = np.asarray(since_s, float)
        use = c & np.all(np.isfinite(F), axis=1) & np.isfinite(since)
        rise = np.where(use, -np.expm1(-self.K * np.where(use, since, 0.0)), 0.0)    # c_k = 1 − e^(−K t)
        steady = use & (since >= self.rise_s - 1e-12)
        key = sid * self.nb + np.asarray(link, int)
        ones = np.ones(len(c))
        st, us = np.flatnonzero(steady), np.flatnonzero(use)
        sums = np.array(self.binned(key, len(starts), [
            (st, F[:, 0]), (st, F[:, 1]), (st, rise), (st, ones),
            (us, F[:, 0]), (us, F[:, 1]), (us, rise), (us, ones)]))

        def add(ep, i, a, b):
            ep[:-1] += sums[:, i]
            ep[-1] = max(ep[-1, 0], rho)

        self.extend(starts, stops, continued, len(c), lambda a: self._new(), add)

    def mean(self, link: int, sigma_per_sample: dict | None = None) -> dict:
        """The next closed interval's rise-corrected mean force on ``link`` (Fx_N, Fz_N; NaN
        without a sample), how many samples it used, and with ``sigma_per_sample`` ({"Fx_N": σ,
        "Fz_N": σ}, the per-sample 1σ) the 1σ of the mean (``Fx_N_error_estimate``, ...)."""
        ep = self.closed.pop(0)
        k = dict(zip(self.KEYS, ep[:-1, link]))
        rho = float(ep[-1, 0])
        steady = k["n"] > 0
        sx, sz, cc, n = ((k["Fx"], k["Fz"], k["c"], k["n"]) if steady else
                         (k["Fx_all"], k["Fz_all"], k["c_all"], k["n_all"]))
        nan = float("nan")
        out = {"Fx_N": float(sx / cc) if cc > 0 else nan, "Fz_N": float(sz / cc) if cc > 0 else nan,
               "force_samples": int(n), "force_steady": bool(steady)}
        for key, sd in (sigma_per_sample or {}).items():
            out[f"{key}_error_estimate"] = (float(sd * min(np.sqrt(rho * n), n) / cc)
                                            if sd is not None and cc > 0 else None)
        return out


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
        self.steady = SteadyForce(self.N, gain_per_s)
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
        breaks = self.tracker.feed(t, r_obs, q, contact, link, bound2, (W, nt.S0, nt.S1, idx))
        rho = float(np.max(np.linalg.eigvals(np.linalg.solve(nt.R, nt.Omega)).real))
        self.steady.feed(contact, link, force, since_s, breaks, rho)
        return breaks

    def finish(self):
        self.tracker.finish()
        self.steady.finish()

    # ---------------------------------------------------------------- per interval
    def fields(self, link: int, well_conditioned: bool, row: dict | None = None) -> dict:
        """The next closed episode's fields on ``link`` (the interval's most frequent one):
        α, p, their 1σ, the bounds and the ratio; NaN with a reason where it is refused; the
        interval's mean force from its steady samples with its 1σ (``SteadyForce``; ``row``: the
        interval's row with the per-sample 1σ of the force, ``F*_N_error_estimate``)."""
        force = self._force(link, row or {})
        out = self._point(link, well_conditioned)
        out.update(force)
        return out

    def _force(self, link: int, row: dict) -> dict:
        sigma = {k: row.get(f"{k}_error_estimate") for k in ("Fx_N", "Fz_N") if f"{k}_error_estimate" in row}
        f = self.steady.mean(link, sigma)
        method = FORCE_METHOD.format(rise=self.steady.rise_s, n=RISE_TIME_CONSTANTS)
        if not f.pop("force_steady"):
            method = method.replace("steady samples", "samples (none steady: the interval is shorter than "
                                    "the observer's rise)")
        for k in sigma:
            f[f"{k}_error_per_sample"] = sigma[k]                  # the per-sample 1σ it came from
            f[f"{k}_error_method"] = method if f.get(f"{k}_error_estimate") is not None else row.get(
                f"{k}_error_method")
        return f

    def _point(self, link: int, well_conditioned: bool) -> dict:
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
