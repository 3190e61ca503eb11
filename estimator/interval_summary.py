"""Contact intervals summarized across chunk boundaries, and their first-order error estimates.

``EpisodeAccumulator`` merges the per-sample answers into intervals from running sums (bounded
memory): per interval the most frequent link and, over its samples on that link, the means of α,
F and p and the well-conditioned fraction; it keeps the samples 2^j − 1 after the interval's
start (O(log L) rows) for the representative sample of the error estimate. ``episode_errors``
propagates the residual's no-contact covariance through the least-squares localization there
(J R Jᵀ, J = ∂(α, F, p)/∂r by central differences); ``add_model_error`` adds the model
uncertainty's term in quadrature.
"""

from __future__ import annotations

import numpy as np

from estimator import localization as loc_mod
from estimator.interval_runs import IntervalRuns

ERROR_METHOD = ("first-order propagation of the residual's no-contact covariance through the "
                "least-squares localization at one sample of the episode (the kept sample 2^j − 1 "
                "samples after its start nearest below its middle), 1σ per sample")


def episode_errors(robot, q_rows, r_rows, R, loc_kwargs, h=1e-4, R_propagated=None):
    """Per episode: 1σ of α, Fx, Fz, px, pz, J R Jᵀ with J = ∂(α, F, p)/∂r by central differences
    of localize_dynamic at the episode's representative sample (q_loc, r rows given, (E, n));
    R (n, n) for every episode or (E, n, n) (noise + the model-error term at that sample) weights
    the fit; ``R_propagated`` (default R) is the covariance propagated (e.g. the model term alone)."""
    E, n = r_rows.shape
    eye = np.eye(n) * h
    rp = np.concatenate([r_rows[:, None] + eye, r_rows[:, None] - eye], axis=1).reshape(-1, n)
    qp = np.repeat(q_rows, 2 * n, axis=0)
    W = np.linalg.inv(R)
    if W.ndim == 3:                                              # one R per episode
        W = np.repeat(W, 2 * n, axis=0)
    res = loc_mod.localize_dynamic(robot, qp, rp, weight=W, **loc_kwargs)
    y = np.concatenate([res.alpha[:, None], res.force_N, res.point_m], axis=1).reshape(E, 2 * n, 5)
    J = (y[:, :n] - y[:, n:]) / (2 * h)                           # (E, n, 5)
    out = []
    for e in range(E):
        Rp = R if R_propagated is None else R_propagated
        cov = J[e].T @ (Rp if np.ndim(Rp) == 2 else Rp[e]) @ J[e]
        sd = np.sqrt(np.clip(np.diagonal(cov), 0, None))
        row = {}
        for j, key in enumerate(["alpha", "Fx_N", "Fz_N", "px_m", "pz_m"]):
            v = float(sd[j])
            row[f"{key}_error_estimate"] = v if np.isfinite(v) else None
            row[f"{key}_error_method"] = ERROR_METHOD if np.isfinite(v) else \
                "not available: the localization refused a perturbed answer (ill-conditioned)"
        out.append(row)
    return out


def add_model_error(row: dict, model: dict):
    """The episode's 1σ with the model-uncertainty term added in quadrature (σ² = σ_noise² +
    σ_model²; the position's from its components)."""
    for key in ("alpha", "px_m", "pz_m"):
        e, m = row.get(f"{key}_error_estimate"), model.get(f"{key}_error_estimate")
        if e is None or m is None:
            continue
        row[f"{key}_error_estimate"] = float(np.hypot(e, m))
        row[f"{key}_error_method"] = row.get(f"{key}_error_method", "") + \
            " + the model uncertainty's term at the representative sample (systematic, not averaged)"
    if row.get("position_m_error_estimate") is not None and row.get("px_m_error_estimate") is not None:
        row["position_m_error_estimate"] = float(np.hypot(row["px_m_error_estimate"], row["pz_m_error_estimate"]))
        if row.get("position_bound_m"):
            row["error_over_bound"] = row["position_m_error_estimate"] / row["position_bound_m"]


class EpisodeAccumulator(IntervalRuns):
    """Contact intervals merged across chunk boundaries from running sums (bounded memory; the
    intervals of estimator.interval_runs).

    Per interval: the most frequent link, and over its samples on that link with a finite α the
    means of α, p, over those with a finite F the mean F (sums in sample order), the
    well-conditioned fraction; the representative sample for the error estimate is kept from
    the samples 2^j − 1 after the start (O(log L) rows)."""

    KEYS = ("alpha", "px", "pz", "Fx", "Fz")

    def _new(self, g, t):
        return {"g0": g, "t0": t, "t1": t, "n": 0, "counts": np.zeros(self.nb),
                "good": np.zeros(self.nb), "same": np.zeros(self.nb),
                "sums": {k: np.zeros(self.nb) for k in self.KEYS}, "kept": []}

    def feed(self, g0, t, contact, link, alpha, Fx, Fz, px, pz, q_loc, rT, G=None, breaks=None):
        """``G`` (T, n, c): the model term's factor per sample (None without one); ``breaks`` (T,)
        bool: a new interval starts at this contact sample (a slide)."""
        starts, stops, continued, sid = self.runs(contact, breaks)
        if not starts.size:
            return
        on = np.flatnonzero(np.asarray(contact, bool))
        good = on[np.isfinite(alpha[on])]                # α, p: the well-conditioned samples
        same = on[np.isfinite(Fx[on])]                   # F: the samples with a force
        key = sid * self.nb + np.asarray(link, int)
        counts, gcount, scount, *sums = self.binned(key, len(starts), [
            (on, None), (good, None), (same, None), (good, alpha), (good, px), (good, pz),
            (same, Fx), (same, Fz)])
        sums = dict(zip(("alpha", "px", "pz", "Fx", "Fz"), sums))

        def add(ep, i, a, b):
            off0 = g0 + a - ep["g0"]
            j = 1
            while j - 1 < off0 + (b - a):        # keep samples at offsets 2^j − 1
                if j - 1 >= off0:
                    k = a + (j - 1 - off0)
                    ep["kept"].append((j - 1, q_loc[k].copy(), rT[:, k].copy(),
                                       None if G is None else G[k].copy()))
                j *= 2
            ep["n"] += b - a
            if b > a:                            # b == a: it ended at the chunk boundary
                ep["t1"] = float(t[b - 1])
            ep["counts"] += counts[i]
            ep["good"] += gcount[i]
            ep["same"] += scount[i]
            for k in self.KEYS:
                ep["sums"][k] += sums[k][i]

        self.extend(starts, stops, continued, len(contact), lambda a: self._new(g0 + a, float(t[a])), add)

    @staticmethod
    def summary(ep) -> dict:
        counts = ep["counts"].copy()
        counts[0] = 0
        link = int(np.argmax(counts)) if counts.any() else 0
        good, same = ep["good"][link], ep["same"][link]
        mean = (lambda k: float(ep["sums"][k][link] / good) if good else float("nan"))
        fmean = (lambda k: float(ep["sums"][k][link] / same) if same else float("nan"))
        return {"t_start_s": ep["t0"], "t_end_s": ep["t1"], "samples": int(ep["n"]), "link": link,
                "alpha": mean("alpha"), "Fx_N": fmean("Fx"), "Fz_N": fmean("Fz"),
                "px_m": mean("px"), "pz_m": mean("pz"),
                "well_conditioned_fraction": float(good / ep["n"])}

    @staticmethod
    def representative(ep):
        """(q_loc, r, G) at the kept offset 2^j − 1 nearest below the middle (L − 1) // 2 (G: the
        model-error term's Φ S there, or None)."""
        mid = (ep["n"] - 1) // 2
        best = max((k for k in ep["kept"] if k[0] <= mid), key=lambda k: k[0])
        return best[1], best[2], best[3]
