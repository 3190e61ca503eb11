"""The whole estimator on a 3-D log: observer → chi-square detection → surface localization,
chunk by chunk (the same numbers whatever the chunk size).

Detection: s_k = r_kᵀ R_k⁻¹ r_k on the rows that are equations (six base rows, sensed joints),
R_k the no-contact covariance of the residual at the posture (estimator.spatial.noise; one per
``cov_stride_s`` block), flagged when s_k > h with P(χ²_n > h) = α per sample (α from the
false-alarm rate). Localization (estimator.spatial.localize) on the flagged samples with the
same whitening, at the posture q(t − lag) (the residual lags τ_ext by about 1/K,
``observer.lag_s``); the point found in the body frame is reported at the current posture.

Episodes, as on the planar chain: a contact ends within a sample or two by the release test
(estimator.release: a CUSUM of the released/held likelihood ratio on the observer's drive,
weighted by the drive's long-run covariance Ω⁻¹ of ``noise.residual_moments``; the chi-square test
then reads the residual minus the released contact's decaying tail, so a new contact right after
shows at once), and the localization reads the observer restarted at each contact's onset
(estimator.onset: r̃_k = r_k − exp(−K(t_k − t_s)) r_s; the onset step's trapezoid error and the
previous contact's tail are dropped). Both work on the world-frame rows with one covariance per
``cov_stride_s`` block; with the model-uncertainty term the release test is off (it whitens by
sensor noise alone) and a contact ends when the statistic falls under the threshold.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from estimator import observer as obs
from estimator import onset, release
from estimator.noise import per_sample_rate
from estimator.spatial import localize as loc
from estimator.spatial import noise as snoise
from estimator.spatial.geometry import body_surfaces
from estimator.spatial.observer import ObserverRun, gains, used_rows
from estimator.spatial.tree import body_poses, whitened_statistic

OUT_COLUMNS = ["t", "contact", "link", "px", "py", "pz", "Fx", "Fy", "Fz", "lx", "ly", "lz",
               "rnorm", "reason"]


@dataclass
class SpatialEstimate:
    frame: object                 # pandas DataFrame, OUT_COLUMNS
    residual: np.ndarray          # (T, nv)
    intervals: list
    info: dict = field(default_factory=dict)

    def summary(self) -> dict:
        f = self.frame
        c = f["contact"].to_numpy().astype(bool)
        names, counts = np.unique(f["reason"].to_numpy()[c].astype(str), return_counts=True)
        return {"samples": int(len(f)), "contact_samples": int(c.sum()),
                "flags_during_contact": {str(k): int(v) for k, v in zip(names, counts)},
                "intervals": self.intervals, **self.info}


class SpatialStream:
    """Feed ``SpatialLog`` chunks (``feed``), then ``finish``; ``parts`` holds per-sample frames."""

    def __init__(self, model, period_s: float, *, gain_per_s=100.0, noise=None, timing=None,
                 false_alarm_rate=(1.0, "h"), lag_compensation: bool = True,
                 cov_stride_s: float = 0.01, min_force_N: float = 0.05, max_condition: float = 20.0,
                 position_tol_m: float = 0.005, threshold: float | None = None,
                 weighting: str = "whitened", model_cov=None, model_source: str = "",
                 release_test: bool = True, onset_restart: bool = True):
        """``weighting``: the localizer's least squares on the residual whitened by its
        no-contact covariance ("whitened", default), or unweighted ("identity": the planar
        dynamic method's fit, with its ambiguity rule 2·√tr R on the residual norm).
        ``model_cov``: Σ_θ of the file's inertial parameters (``model.model_covariance``); the
        no-contact covariance is then R_k = R_noise + Φ_k Σ_θ Φ_kᵀ (estimator.model_error).
        ``release_test`` / ``onset_restart``: the episode machinery of the module doc."""
        from userio.errors import InputError

        if weighting not in ("whitened", "identity"):
            raise InputError(f"weighting: use 'whitened' or 'identity', got {weighting!r}")
        self.weighting = weighting
        self.model = model
        self.dt = float(period_s)
        self.gain = gain_per_s
        self.K = gains(model, gain_per_s)
        self.noise = snoise.default_noise(model) if noise is None else noise
        self.timing = timing
        self.rows = used_rows(model)
        self.obs = ObserverRun(model, gain_per_s, self.dt, "exact", timing)
        self.alpha = per_sample_rate(*false_alarm_rate, self.dt)
        from scipy.special import chdtri

        self.threshold = threshold
        self.h = float(chdtri(len(self.rows), self.alpha))
        self.stride = max(1, int(round(cov_stride_s / self.dt)))
        self.surfaces = body_surfaces(model.robot, model.tree)
        self._link_names = sorted({""} | {sf.name for sf in self.surfaces}
                                  | {n for sf in self.surfaces for n, _ in sf.solids})
        self.lag = float(np.mean(obs.lag_s(self.K, self.dt))) if lag_compensation else 0.0
        self.past = None
        self.g = 0
        self.min_force_N, self.max_condition, self.position_tol_m = min_force_N, max_condition, position_tol_m
        self.parts, self.residuals = [], []
        self._floor = None
        self._cur = None                 # (block index, L⁻¹, R, Ω⁻¹) of the block the last chunk ended in
        # Without joint-rate or encoder noise the covariance depends on the posture only through
        # the base orientation, which turns the world force rows: R(q) = D R₀ Dᵀ with
        # D = diag(R_wb, I) (the six wrench channels share one timing and the force rows one
        # gain). Then ‖L(q) r‖ = ‖L₀ Dᵀ r‖ with one constant L₀: exact, and no covariance per block.
        self.info = {}
        K = self.K[:3]
        self._L0 = None
        self.model_term = None
        if model_cov is not None:
            from estimator.model_error import ModelTerm

            self.model_term = ModelTerm(model, model_cov, self.K, self.dt, "exact")
            self.info["model_uncertainty_source"] = model_source
        else:
            self.info["model_uncertainty_source"] = model_source or "none"
        self.release = None
        self.restart = onset.RestartState() if onset_restart else None
        if threshold is None and release_test and self.model_term is None:
            self.release = release.ReleaseState()
            self.h_release = float(np.log(1.0 / self.alpha))
            self.info.update(release_test="CUSUM of the released/held log-likelihood ratio on the "
                                          "observer's drive (estimator.release)",
                             release_threshold=self.h_release)
        elif release_test:
            self.info["release_test"] = ("off: the model-uncertainty term is in the statistic"
                                         if threshold is None else "off: --threshold")
        self.info["onset_restart"] = bool(onset_restart)
        if (self.noise.velocity_sigma_rad_per_s == 0 and self.noise.encoder_counts == 0
                and not np.any(self.noise.base_sigma > 0)
                and np.all(K == K[0]) and self.model_term is None and self.release is None):
            q0 = model.robot.rest_q()
            q0[3:7] = [0.0, 0.0, 0.0, 1.0]
            R0 = snoise.residual_covariance(model, q0[None], np.zeros((1, model.n_v)), self.noise,
                                            self.gain, self.dt, timing)[0]
            self._L0 = np.linalg.inv(np.linalg.cholesky(R0))
            self._floor = max(min_force_N, 5.0 * float(np.sqrt(np.max(np.diagonal(R0)[:3]))))
            self._amb = 2.0 * float(np.sqrt(np.trace(R0)))
            self.info.update(min_force_N=self._floor, residual_sigma=np.sqrt(np.diagonal(R0)).tolist(),
                             covariance="posture-independent up to the base orientation (one whitener)")
        else:
            self.info["covariance"] = f"posture-dependent, one per {self.stride} samples"
        self.info.update({"detector": ("chi-square on the whitened residual" if threshold is None
                                  else "||r|| > threshold"),
                     "false_alarm_probability_per_sample": self.alpha,
                     "false_alarm_rate_per_s": self.alpha / self.dt, "chi2_threshold": self.h,
                     "chi2_dof": int(len(self.rows)), "residual_noise_source": self.noise.describe(),
                     "rows": ["Fx_world", "Fy_world", "Fz_world", "Mx_base", "My_base", "Mz_base"]
                     + [f"tau_{model.joint_names[k - 6]}" for k in self.rows[6:]],
                     "lag_compensation_s": self.lag,
                     "identifiability": loc.identifiability(model, self.surfaces)})

    def _whiteners(self, q, v, g0, tau=None):
        """(L⁻¹ per block (B, nu, nu), block of each sample (T,)): one covariance per stride
        block (block index (g0 + i) // stride) at the block's first sample; a block that began
        in the previous chunk keeps its L⁻¹ (the numbers do not depend on the chunk sizes)."""
        T = len(q)
        blocks = (g0 + np.arange(T)) // self.stride
        first = np.r_[0, np.flatnonzero(np.diff(blocks)) + 1]
        carried = self._cur is not None and self._cur[0] == blocks[0]
        new = first[1:] if carried else first
        Linv = np.empty((len(first), len(self.rows), len(self.rows)))
        self._Rn = np.empty_like(Linv)                 # the noise covariances (model term: R_noise)
        self._Wb = np.empty_like(Linv)                 # Ω⁻¹: the release test's weights
        if new.size:
            wrench = None               # base-state noise: linearized at the measured wrench
            if tau is not None and np.any(self.noise.base_sigma > 0):
                wrench = self.model.ft_from_base_rows(q[new], tau[new, :6])
            R, Om = snoise.residual_moments(self.model, q[new], v[new], self.noise, self.gain,
                                            self.dt, self.timing, wrench)
            self._Rn[1 if carried else 0:] = R
            self._Wb[1 if carried else 0:] = np.linalg.inv(Om)
            Linv[1 if carried else 0:] = np.linalg.inv(np.linalg.cholesky(R))
            if self._floor is None:
                self._floor = max(self.min_force_N, 5.0 * float(np.sqrt(np.max(np.diagonal(R[0])[:3]))))
                self.info["min_force_N"] = self._floor
                self.info["residual_sigma"] = np.sqrt(np.diagonal(R[0])).tolist()
                self._amb = 2.0 * float(np.sqrt(np.trace(R[0])))
        if carried:
            Linv[0], self._Rn[0], self._Wb[0] = self._cur[1], self._cur[2], self._cur[3]
        self._cur = (int(blocks[-1]), Linv[-1].copy(), self._Rn[-1].copy(), self._Wb[-1].copy())
        return Linv, np.searchsorted(first, np.arange(T), side="right") - 1

    def _process(self, rows):
        import pandas as pd

        t, q, v, r = rows["t"], rows["q"], rows["v"], rows["r"]
        T = len(t)
        if self._L0 is not None:
            from estimator.spatial.model import quat_rotate

            rb = r.copy()
            rb[:, :3] = quat_rotate(q[:, 3:7], r[:, :3], inverse=True)     # Dᵀ r
            stat = whitened_statistic(rb, self.rows, self._L0[None], np.zeros(T, np.int64))
        else:
            Lb, block = self._whiteners(q, v, self.g, rows.get("tau"))
            if self.release is not None:         # chi-square with the release test
                contact, stat, _ = release.detect(
                    t, np.ascontiguousarray(r[:, self.rows]), self.K[self.rows], Lb, self._Wb,
                    block, self.h, self.h_release, self.release)
            elif self.model_term is None:
                stat = whitened_statistic(r, self.rows, Lb, block)
            else:
                stat, Gu = self._model_statistic(t, q, v, r, block)
        if self.release is not None:
            rnorm = np.sqrt(stat)
        elif self.threshold is None:
            contact, rnorm = stat > self.h, np.sqrt(stat)
        else:
            rnorm = np.linalg.norm(r[:, self.rows], axis=1)
            contact = rnorm > self.threshold
        q_loc = q
        if self.lag > 0:
            pt, pq = (t, q) if self.past is None else (np.r_[self.past[0], t], np.vstack([self.past[1], q]))
            x = t - self.lag
            q_loc = np.empty_like(q)
            for k in range(q.shape[1]):
                q_loc[:, k] = np.interp(x, pt, pq[:, k])
            keep = int(np.ceil(1.02 * self.lag / self.dt)) + 2
            self.past = (pt[-keep:], pq[-keep:])
        r_obs = r
        if self.restart is not None:          # localize on the observer restarted at the onset
            r, _ = onset.restart(t, r, contact, self.K, self.restart)
        sel = np.flatnonzero(contact)
        link = np.full(T, "", dtype=object)
        pw = np.full((T, 3), np.nan)
        pl = np.full((T, 3), np.nan)
        F = np.full((T, 3), np.nan)
        reason = np.full(T, loc.REASONS[loc.NO_CONTACT], dtype=object)
        if sel.size:
            ident = self.weighting == "identity"
            if ident:
                W = np.eye(len(self.rows))
            elif self._L0 is not None:                      # L₀ Dᵀ at the localization posture
                from estimator.spatial.tree import quat_matrix

                W = np.broadcast_to(self._L0, (sel.size,) + self._L0.shape).copy()
                W[:, :, :3] = self._L0[:, :3] @ quat_matrix(q_loc[sel, 3:7]).transpose(0, 2, 1)
            elif self.model_term is not None:           # R_k = R_noise + G_k G_kᵀ
                Rk = self._Rn[block[sel]] + np.einsum("tic,tjc->tij", Gu[sel], Gu[sel])
                W = np.linalg.inv(np.linalg.cholesky(Rk))
            else:
                W = Lb[block[sel]]
            res = loc.localize(self.model, self.surfaces, q_loc[sel], r[sel], W,
                               min_force_N=self._floor, max_condition=self.max_condition,
                               position_tol_m=self.position_tol_m,
                               ambiguity_tol=self._amb if ident else None)
            R, p, _, _ = body_poses(self.model.tree, q[sel])
            bi = np.maximum(res.body, 0)
            ii = np.arange(sel.size)
            world = p[ii, bi] + np.einsum("sij,sj->si", R[ii, bi], res.point_body)
            pw[sel] = world
            pl[sel] = res.point_body
            F[sel] = res.force_N
            link[sel] = res.link
            reason[sel] = np.asarray(loc.REASONS, dtype=object)[res.reason]
        self.g += T
        self.residuals.append(r_obs)
        self.parts.append(pd.DataFrame({"t": t, "contact": contact.astype(int),
                                        "link": pd.Categorical(link, categories=self._link_names),
                                        "px": pw[:, 0], "py": pw[:, 1], "pz": pw[:, 2],
                                        "Fx": F[:, 0], "Fy": F[:, 1], "Fz": F[:, 2],
                                        "lx": pl[:, 0], "ly": pl[:, 1], "lz": pl[:, 2],
                                        "rnorm": rnorm,
                                        "reason": pd.Categorical(reason, categories=loc.REASONS)},
                                       columns=OUT_COLUMNS))

    def _model_statistic(self, t, q, v, r, block):
        """(s_k, G_k) with R_k = R_noise + G_k G_kᵀ on the used rows, G = Φ S from the model
        term (estimator.model_error; its own statistic over all rows is not used: an unsensed
        joint's row is no equation)."""
        from estimator.model_error import statistic_numpy

        n, rows = self.model.n_v, self.rows
        Rfull = np.broadcast_to(np.eye(n), (len(self._Rn), n, n)).copy()
        Rfull[np.ix_(np.arange(len(self._Rn)), rows, rows)] = self._Rn
        _, G = self.model_term.statistic(t, q, v, np.ascontiguousarray(r.T), Rfull,
                                         block.astype(np.int64))
        Gu = G[:, rows]
        return statistic_numpy(r[:, rows].T, Gu, self._Rn, block), Gu

    def feed(self, log):
        rows = self.obs.feed(log.t, log.q, log.v, log.tau_meas(self.model))
        if rows is not None:
            self._process(rows)

    def finish(self) -> SpatialEstimate:
        import pandas as pd

        nv = self.model.n_v
        rows = self.obs.feed(np.zeros(0), np.zeros((0, nv + 1)), np.zeros((0, nv)),
                             np.zeros((0, nv)), final=True)
        if rows is not None:
            self._process(rows)
        frame = pd.concat(self.parts, ignore_index=True) if self.parts else pd.DataFrame(columns=OUT_COLUMNS)
        for c in ("link", "reason"):             # plain strings for the reader of the frame
            frame[c] = frame[c].astype(object)
        r = np.concatenate(self.residuals) if self.residuals else np.zeros((0, nv))
        return SpatialEstimate(frame=frame, residual=r, intervals=intervals(frame), info=self.info)


def intervals(frame) -> list[dict]:
    """Contact intervals: start/end, samples, the most frequent link, and over its samples with a
    surface answer ('ok'; 'no_geometry' on a segment) the median point (world and link frame)
    and force (the median: the onset and the residual's decay after the contact ends are the
    samples least well explained, and a few of them do not move it)."""
    c = frame["contact"].to_numpy().astype(bool)
    if not c.any():
        return []
    edges = np.diff(np.r_[0, c.astype(int), 0])
    starts, stops = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
    out = []
    t = frame["t"].to_numpy()
    links = frame["link"].to_numpy()
    good_all = (frame["reason"].to_numpy() == "ok") | (frame["reason"].to_numpy() == "no_geometry")
    for a, b in zip(starts, stops):
        seg = links[a:b][good_all[a:b]]
        names, counts = np.unique(seg.astype(str), return_counts=True) if seg.size else ([], [])
        link = str(names[int(np.argmax(counts))]) if len(names) else ""
        m = np.zeros(len(frame), bool)
        m[a:b] = good_all[a:b] & (links[a:b] == link)
        mean = lambda k: float(np.median(frame[k].to_numpy()[m])) if m.any() else float("nan")  # noqa: E731
        out.append({"t_start_s": float(t[a]), "t_end_s": float(t[b - 1]), "samples": int(b - a),
                    "link": link, "located_fraction": float(m.sum() / (b - a)),
                    **{f"{k}_m" if k[0] in "pl" else f"{k}_N": mean(k)
                       for k in ("px", "py", "pz", "lx", "ly", "lz", "Fx", "Fy", "Fz")}})
    return out


def estimate_log(model, chunks, period_s, **kw) -> SpatialEstimate:
    stream = SpatialStream(model, period_s, **kw)
    for c in chunks:
        stream.feed(c)
    return stream.finish()
