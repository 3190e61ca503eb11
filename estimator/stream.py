"""The estimator over a log fed in chunks, in bounded memory: ``EstimatorStream``.

Per chunk: the observer (``observer.ObserverRun``), detection on its residual, then, once the
noise floors are known, localization and the contact intervals. Everything that spans a chunk
boundary is carried in the stream's state: the observer (last row's r, P, u, τ), the rows a group
delay reads ahead, the past postures for the lag compensation, the detector's state
(``detection.DetectorState``: debounce run; the CUSUM's), the open contact episode's running sums.
Any chunk sizes give the same per-sample numbers, bit for bit. ``estimator.estimate`` sets a
stream up for a log and runs it.
"""

from __future__ import annotations

import numpy as np

from estimator import compiled, cusum_calibration, detection, intervals, localization_loops
from estimator import localization as loc_mod
from estimator import noise as noise_mod
from estimator import observer, onset, release, sequential
from estimator import timing as timing_mod
from estimator.contact_estimate import ContactEstimate
from estimator.detection import DetectorState, chi2_isf, debounce_chunk, sumsq_rows, whitened_sumsq
from userio.errors import InputError
from estimator.interval_summary import EpisodeAccumulator, add_model_error, episode_errors

METHODS = ("dynamic", "paper")
DEFAULT_FALSE_ALARM_RATE = (1.0, "h")
STATS_SAMPLES = 65536           # the noise floors come from the contact-free samples among these
WORK_SAMPLES = 16384            # samples per piece of work inside a chunk (cache-sized)


def _fit_weights(rec, sel, T: int, n: int, row_weights):
    """The localization's weights for the selected samples: W = R⁻¹ from the detector's whitening
    blocks L⁻¹ (W = L⁻ᵀL⁻¹; the maximum-likelihood fit; the noise covariance R is the detector's,
    per posture block), with the robot's model term where it has one,

        W_k = (R_b(k) + G_k G_kᵀ)⁻¹        (estimator.model_error: R_model,k = G_k G_kᵀ),

    the fit the detector's statistic assumes (a fit weighted by R⁻¹ alone over-trusts the rows the
    model error lives in, and its misfit χ² (estimator.misfit) is then judged against the noise
    alone); else the diagonal ``row_weights`` (the paper rule: no noise model)."""
    if rec.get("Linv") is None:
        return loc_mod.weight_blocks(n, T, row_weights)[0], \
            np.zeros(T, np.int64)[sel]
    Linv, idx = rec["Linv"]
    W = np.einsum("bki,bkj->bij", Linv, Linv)
    G = rec.get("G")
    if G is None:
        return W, idx[sel]
    Gs = G[sel]
    R = np.linalg.inv(W)[idx[sel]] + np.einsum("tic,tjc->tij", Gs, Gs)
    return np.linalg.inv(R), np.arange(len(Gs))


class EstimatorStream:
    """The estimator over a log fed in chunks (``feed``), in bounded memory; ``finish`` ends it.

    Each call returns the ``ContactEstimate`` parts ready so far (per-sample arrays for a run of
    consecutive samples; possibly none). Per-sample results do not depend on the chunk sizes.
    The quantities that ``estimate`` once took from the whole log are fixed by rules that
    stream exactly:

    * sampling period: the median of the first 1024 steps (``observer.regular_period``, or the
      period the log reader found with the same rule);
    * noise floors (force floor, ambiguity tolerance, the paper method's isolation thresholds)
      and the summary covariance (the median of the posture-dependent covariances): from the
      contact-free samples (covariance blocks) among the first ``stats_samples`` samples of the
      log (65 536 by default; the whole log when it is shorter). Localization waits until those
      samples are in (they are held, observer and detection done);
    * an episode's per-sample error estimate of F: at the sample 2^j − 1 samples after its start
      nearest below its middle (``EpisodeAccumulator``), not its exact middle (which needs the
      episode's end); its point and ± (estimator.intervals) are sums over all its samples.
    """

    def __init__(self, robot, method: str = "dynamic", gain_per_s=100.0,
                 threshold: float | None = None, debounce: int = 0, expected=(), *,
                 period_s: float, discretization: str = "exact", row_weights=None,
                 min_force_N: float = 0.05, max_condition: float = 20.0,
                 isolation_floor: float = 0.01, lag_compensation: bool = True, timing=None,
                 timing_source: str = "option", noise=None, residual_cov=None,
                 residual_cov_source: str = "", false_alarm_rate=DEFAULT_FALSE_ALARM_RATE,
                 cov_stride_s: float = 0.01, stats_samples: int = STATS_SAMPLES,
                 detector: str = "chi2", cusum_calibration=None, isolation_quiet: bool = False,
                 model_cov=None, model_cov_source: str = "",
                 residual_drive=None, release_test: bool = True, onset_restart: bool = True):
        if method not in METHODS:
            raise InputError(f"method: unknown {method!r}; use one of {', '.join(METHODS)}")
        if detector not in sequential.DETECTORS:
            raise InputError(f"detector: unknown {detector!r}; use one of "
                             f"{', '.join(sequential.DETECTORS)}")
        if detector != "chi2" and (method == "paper" or threshold is not None):
            raise InputError(f"detector {detector}: works on the whitened residual of the dynamic "
                             "method; not with --method paper or --threshold")
        if int(debounce) != debounce or debounce < 0:
            raise InputError(f"debounce: must be a whole number of samples ≥ 0, got {debounce}")
        self.robot, self.method, self.expected = robot, method, tuple(expected)
        self.full = observer.full_robot(robot)
        self.dt = float(period_s)
        self.K = observer.gains(robot, gain_per_s)
        self.gain_per_s = gain_per_s
        self.n = self.K.size
        self.debounce = int(debounce)
        self.row_weights = row_weights
        self.min_force_N, self.max_condition = min_force_N, max_condition
        self.isolation_floor = isolation_floor
        self.stats_samples = int(stats_samples)
        self.timing = timing
        self.obs = observer.ObserverRun.planar(robot, self.K, self.dt, discretization, timing)
        self.state = DetectorState()
        self.misfit = None               # MisfitTally of the whitened localization fits (dynamic, χ²)
        self.info = {"timing": timing_mod.describe(timing), "timing_source": timing_source}
        self.R = self.Linv = None
        self._post = None                # posture(s) of the covariance block(s): (q, q̇)
        self.stride = None
        self._R_head = []                # posture-dependent covariances of the head's blocks
        self.detector, self.cusum_cal = detector, cusum_calibration
        self.noise = noise_mod.paper_leg_noise() if noise is None else noise
        value, unit = false_alarm_rate if isinstance(false_alarm_rate, tuple) else (false_alarm_rate, "s")
        self.alpha = noise_mod.per_sample_rate(value, unit, self.dt)
        self.isolation_quiet, self._R_iso = isolation_quiet, None
        if method == "paper" or threshold is not None:
            threshold = 0.06 if threshold is None else threshold
            if not (np.isfinite(threshold) and threshold > 0):
                raise InputError(f"threshold: must be a finite number > 0, got {threshold}")
            self.chi2 = False
            self.h = float(threshold)
            self.info.update(detector="paper rule ||r|| > threshold", threshold=threshold)
        else:
            self.chi2 = True
            alpha = self.alpha
            self.h = chi2_isf(alpha, self.n)
            if residual_cov is not None:
                self._set_R(np.asarray(residual_cov, float))
                source = residual_cov_source
            else:
                if not (self.noise.velocity_sigma_rad_per_s == 0 and self.noise.encoder_counts == 0):
                    self.stride = max(1, int(round(cov_stride_s / self.dt)))
                source = "sensor noise model, " + self.noise.describe()
            self.info.update({"detector": "chi-square on the whitened residual",
                              "false_alarm_probability_per_sample": alpha,
                              "false_alarm_rate_per_s": alpha / self.dt, "chi2_threshold": self.h,
                              "chi2_dof": self.n, "residual_noise_source": source})
            self.model_term = None
            if model_cov is not None:        # R_k = R_noise + Φ_k Σ_θ Φ_kᵀ (estimator.model_error)
                if detector != "chi2":
                    raise InputError(f"detector {detector}: calibrated for white sensor noise; the "
                                     f"robot's model uncertainty ({model_cov_source}) makes the "
                                     f"residual's error slowly varying: use the chi2 detector, or "
                                     f"--model-uncertainty none")
                from estimator.model_error import ModelTerm

                self.model_term = ModelTerm(self.full, model_cov, gain_per_s, self.dt, discretization)
                self._G_head = []
                self.info["model_uncertainty_source"] = model_cov_source
                self.info["residual_noise_source"] = f"{source}; + model uncertainty ({model_cov_source})"
        if not self.chi2:
            self.model_term = None
        # the localization reads the observer restarted at each contact's onset (estimator.onset)
        self.restart = onset.RestartState() if method == "dynamic" and discretization == "exact" \
            and onset_restart else None
        self.lag = None
        if method == "dynamic" and lag_compensation:
            self.lag = float(np.mean(observer.lag_s(self.K, self.dt, discretization)))
            self.info["lag_compensation_s"] = self.lag
            self._past_rows = int(np.ceil(1.02 * self.lag / self.dt)) + 2
            self._past = None                # (t, q) of the last finalized rows
        self.g = 0                           # samples through detection so far
        self.queue = []                      # detected chunks waiting for the noise floors
        self.stats = None
        self.episodes = EpisodeAccumulator(robot.n_links)
        self.episode_stage = None            # the episode estimate: dynamic, chi-square, no stance
        self.release = None                  # the release test: with the chi-square detector
        if method == "dynamic" and self.chi2 and not self.expected and discretization == "exact":
            self.episode_stage = intervals.EpisodeStage(
                robot, self.K, self.dt, self.noise, gain_per_s, timing, residual_drive)
            if detector == "chi2" and self.debounce == 0 and release_test and self.model_term is not None:
                # the release test whitens the drive by the sensor noise alone; with the model
                # term in R_k a contact ends when the statistic falls under the threshold
                self.info["release_test"] = "off: the model-uncertainty term is in the statistic"
            elif detector == "chi2" and self.debounce == 0 and release_test:
                self.release = release.ReleaseState()
                self.h_release = float(np.log(1.0 / self.alpha))
                self.info.update(release_test="CUSUM of the released/held log-likelihood ratio "
                                              "on the observer's drive (estimator.release)",
                                 release_threshold=self.h_release)
        self.intervals = []
        self.reason_counts = np.zeros(len(loc_mod.REASONS), dtype=np.int64)
        self.samples = self.contact_samples = 0
        self._cur_block = None               # (block index, L⁻¹) of the block spanning chunks

    def _set_R(self, R):
        self.R = R
        self.Linv = np.linalg.inv(np.linalg.cholesky(R))

    # ------------------------------------------------------------------ stage 1
    def _statistic(self, g0, t, q, dq, unexpT):
        """The detector's statistic: ‖r‖ (paper rule) or rᵀR⁻¹r (chi-square) per sample, and the
        model-error term's G = Φ S per sample (None without one)."""
        if not self.chi2:
            return np.sqrt(sumsq_rows(unexpT)), None
        T = unexpT.shape[1]
        if self.R is None and self.stride is None:          # posture-independent: first sample
            R = noise_mod.residual_covariance(self.robot, q[:1], dq[:1], self.noise, self.gain_per_s,
                                              self.dt, self.timing)[0]
            self._set_R(R)
        if self.stride is None:
            if self._post is None:
                self._post = (q[:1].copy(), dq[:1].copy())
            self._weights = (self.Linv[None], np.zeros(T, np.int64))
            if self.model_term is None:
                return whitened_sumsq(unexpT, self.Linv), None
            stat, G = self.model_term.statistic(t, q, dq, unexpT, self.R[None], np.zeros(T, np.int64))
            self._keep_head_G(g0, G)
            return stat, G
        st = self.stride
        blocks = np.arange(g0 // st, (g0 + T - 1) // st + 1)
        new = blocks[blocks * st >= g0]
        Ls, Rs, Ps = {}, {}, {}
        if self._cur_block is not None:
            b0 = self._cur_block[0]
            Ls[b0], Rs[b0], Ps[b0] = self._cur_block[1], self._cur_block[2], self._cur_block[3]
        if new.size:
            Rb = noise_mod.residual_covariance(self.robot, q[new * st - g0], dq[new * st - g0],
                                               self.noise, self.gain_per_s, self.dt, self.timing)
            Lb = np.linalg.inv(np.linalg.cholesky(Rb))
            for b, R, L in zip(new, Rb, Lb):
                Ls[int(b)], Rs[int(b)] = L, R
                Ps[int(b)] = (q[b * st - g0].copy(), dq[b * st - g0].copy())
                if b * st < self.stats_samples:
                    self._R_head.append(R)
        bl = int(blocks[-1])
        self._cur_block = (bl, Ls[bl], Rs[bl], Ps[bl])
        idx = (g0 + np.arange(T)) // st - blocks[0]
        L_all = np.stack([Ls[int(b)] for b in blocks])
        self._weights = (L_all, idx)
        self._post = (np.stack([Ps[int(b)][0] for b in blocks]), np.stack([Ps[int(b)][1] for b in blocks]))
        if self.model_term is not None:
            R_all = np.stack([Rs[int(b)] for b in blocks])
            stat, G = self.model_term.statistic(t, q, dq, unexpT, R_all, idx)
            self._keep_head_G(g0, G)
            return stat, G
        return whitened_sumsq(unexpT, L_all[idx]), None

    def _keep_head_G(self, g0, G):
        """Every 10th sample's G among the first ``stats_samples`` (the median model term)."""
        if g0 < self.stats_samples:
            self._G_head.append(G[:max(0, self.stats_samples - g0):10])

    def _detect(self, stat, q0, dq0):
        """(contact, rnorm) from the statistic; the detector's state carries across chunks.

        CUSUM (estimator.sequential): calibrated once, on the noise model at the log's first
        posture (q0, q̇0) unless the quiet window gave its calibration."""
        if self.detector == "cusum":
            if self.cusum_cal is None:
                self.cusum_cal = cusum_calibration.model_calibration(self.robot, q0, dq0, self.noise,
                                                              self.gain_per_s, self.dt, self.timing)
            if "cusum_threshold" not in self.info:
                h = self.cusum_cal.threshold(self.alpha)
                self.info = cusum_calibration.detector_info(self.info, h, self.cusum_cal)
            contact, self.state.extra["cusum"] = sequential.cusum(
                stat, self.n, self.info["cusum_threshold"], self.cusum_cal.drift,
                self.state.extra.get("cusum"))
            return contact, np.sqrt(stat)
        raw = stat > self.h
        contact = debounce_chunk(raw, self.debounce, self.state) if self.debounce else raw
        return contact, (np.sqrt(stat) if self.chi2 else stat)

    def _stage1(self, rows):
        t, q, dq, tau, rT = rows["t"], rows["q"], rows["dq"], rows["tau"], rows["rT"]
        T = len(t)
        r = rT.T
        ef = None
        if self.expected:
            unexp, ef = loc_mod.explain_expected(self.robot, q, r, self.expected, self.row_weights)
            unexpT = np.ascontiguousarray(unexp.T)
        else:
            unexpT = rT
        self._weights = None
        stat, G = self._statistic(self.g, t, q, dq, unexpT)
        rec = {"Linv": self._weights, "post": self._post}
        if self.release is not None:             # chi-square with the release test (estimator.release)
            W = np.linalg.inv(self.episode_stage.terms(rec).Omega)
            contact, stat, rec["released"] = release.detect(
                t, r, self.K, self._weights[0], W, self._weights[1], self.h, self.h_release,
                self.release)
            rnorm = np.sqrt(stat)
        else:
            contact, rnorm = self._detect(stat, q[0], dq[0])
        if self.method == "paper" and not self.isolation_quiet and self._R_iso is None:
            self._R_iso = noise_mod.residual_covariance(self.robot, q[:1], dq[:1], self.noise,
                                                        self.gain_per_s, self.dt, self.timing)[0]
        q_loc = q
        if self.lag is not None:
            pt, pq = (t, q) if self._past is None else (np.r_[self._past[0], t], np.vstack([self._past[1], q]))
            x = t - self.lag
            q_loc = np.empty_like(q)
            for k in range(q.shape[1]):
                q_loc[:, k] = np.interp(x, pt, pq[:, k])
            self._past = (pt[-self._past_rows:], pq[-self._past_rows:])
        rec.update({"g0": self.g, "t": t, "q": q, "dq": dq, "tau": tau, "rT": rT, "r": r,
                    "contact": contact, "rnorm": rnorm, "q_loc": q_loc, "ef": ef, "G": G})
        self.g += T
        return rec

    # ------------------------------------------------------------------ noise floors
    def _freeze_stats(self):
        S = self.stats_samples
        parts = [(rec, min(len(rec["t"]), S - rec["g0"])) for rec in self.queue if rec["g0"] < S]
        quiet_r = np.concatenate([rec["r"][:m][~rec["contact"][:m]] for rec, m in parts]) \
            if parts else np.zeros((0, self.n))
        quiet_rnorm = np.concatenate([rec["rnorm"][:m][~rec["contact"][:m]] for rec, m in parts]) \
            if parts else np.zeros(0)
        Rm = self.R
        if self.stride is not None and self._R_head:
            Rm = np.median(np.stack(self._R_head), axis=0)
        info = {}
        self.Rm_noise, Rf = Rm, Rm
        if getattr(self, "model_term", None) is not None and Rm is not None and self._G_head:
            G = np.concatenate(self._G_head)
            Rmodel = np.median(np.einsum("tic,tjc->tij", G, G), axis=0)
            info["residual_model_sigma"] = np.sqrt(np.diag(Rmodel)).tolist()
            Rf = Rm + Rmodel             # the force floor sees the model error (a bias of F)
        force_floor = float(detection.noise_thresholds(quiet_r[:, :2], None, floor=self.min_force_N).max())
        if Rm is not None:
            ambiguity_tol = 2.0 * float(np.sqrt(self.n))   # 2 noise norms: the fit is whitened
            force_floor = max(self.min_force_N, 5.0 * float(np.sqrt(max(Rf[0, 0], Rf[1, 1]))))
            info["residual_sigma"] = np.sqrt(np.diag(Rm)).tolist()
        else:
            ambiguity_tol = max(1e-3, 2.0 * float(np.median(quiet_rnorm))) if len(quiet_rnorm) >= 10 else 1e-3
        info.update(min_force_N=force_floor, ambiguity_tol=ambiguity_tol,
                    noise_floor_samples=int(min(S, self.g)))
        thresholds = None
        if self.method == "paper" and self.isolation_quiet:
            thresholds = detection.noise_thresholds(quiet_r[:, 3:], None, floor=self.isolation_floor)
            info.update(isolation_thresholds=thresholds.tolist(),
                        isolation_thresholds_source="robust (MAD) σ of the log's contact-free "
                                                    "samples, max(floor, 5 σ)")
        elif self.method == "paper":       # noise-aware and streamable (detection.whitened_thresholds)
            thresholds = detection.whitened_thresholds(self._R_iso, self.alpha)
            info.update(isolation_thresholds=thresholds.tolist(),
                        isolation_thresholds_source=f"sensor noise model ({self.noise.describe()}), "
                                                    f"per-row false-isolation probability "
                                                    f"{self.alpha:.3g} per sample",
                        isolation_false_alarm_probability_per_sample=self.alpha)
        self.info.update(info)
        self.Rm = Rm
        self.stats = {"force_floor": force_floor, "ambiguity_tol": ambiguity_tol,
                      "thresholds": thresholds}
        self.loc_kwargs = dict(row_weights=self.row_weights, min_force_N=force_floor,
                               max_condition=self.max_condition, ambiguity_tol=ambiguity_tol)

    # ------------------------------------------------------------------ stage 2
    def _stage2(self, rec) -> ContactEstimate:
        t, q, r, contact = rec["t"], rec["q"], rec["r"], rec["contact"]
        T, N = len(t), self.robot.n_links
        r_obs = r
        if self.restart is not None:         # localize on the observer restarted at the onset
            r, rec["since_s"] = onset.restart(t, r, contact, self.K, self.restart)
        else:                                # the running observer: its stationary covariance
            rec["since_s"] = np.where(contact, 1e6, np.nan)
        sel = np.flatnonzero(contact)
        if sel.size == T:
            sel = slice(None)                          # every sample: views, no copies
        n_sel = T if isinstance(sel, slice) else sel.size
        link = np.zeros(T, dtype=int)
        alpha = np.full(T, np.nan)
        force = np.full((T, 2), np.nan)
        point = np.full((T, 2), np.nan)
        condition = np.full(T, np.nan)
        reason = np.full(T, loc_mod.NO_CONTACT, dtype=np.int8)
        expected_force = None
        fused = False
        if self.method == "dynamic":
            weight = _fit_weights(rec, sel, T, self.n, self.row_weights)
            kw = {k: v for k, v in self.loc_kwargs.items() if k != "row_weights"}
            if n_sel and not self.expected and compiled.available():
                # one compiled pass: the fit at q(t − lag), the point at the current posture
                out = localization_loops.localize(self.full, rec["q_loc"][sel], r[sel], weight, q[sel],
                                                  position_tol_m=0.005, bound_tol=0.05, **kw)
                res = loc_mod.Localization(*out[:6], cost=out[6])
                fused = True
            elif n_sel:
                res = loc_mod.localize_dynamic(self.robot, rec["q_loc"][sel], r[sel],
                                               expected=self.expected, weight=weight, **kw)
            if n_sel and not self.expected and rec.get("Linv") is not None and self.n > 3:
                self._tally_misfit(t[sel], res)
            if self.expected:
                expected_force = np.full((T, len(self.expected), 2), np.nan)
                quiet = np.flatnonzero(~contact)
                expected_force[quiet] = rec["ef"][quiet]
                if n_sel:
                    expected_force[sel] = res.expected_force_N
        elif n_sel:
            iso = detection.isolate(r[sel, 3:], self.stats["thresholds"])
            res = loc_mod.localize_paper(self.robot, q[sel], rec["dq"][sel], rec["tau"][sel], iso,
                                         min_force_N=self.stats["force_floor"],
                                         max_condition=self.max_condition)
        if n_sel:
            if self.method == "dynamic" and not fused:    # the point at the current posture from α
                qs = q[sel]
                jx, jz = loc_mod._joints_link_major(self.full, qs)
                c0 = np.clip(res.link - 1, 0, N - 1)
                sx, sz = loc_mod._pick(jx[:-1], c0), loc_mod._pick(jz[:-1], c0)
                ex, ez = loc_mod._pick(jx[1:], c0), loc_mod._pick(jz[1:], c0)
                res.point_m = np.stack([qs[:, 0] + sx + res.alpha * (ex - sx),
                                        qs[:, 1] + sz + res.alpha * (ez - sz)], axis=-1)
            link[sel] = res.link
            alpha[sel] = res.alpha
            force[sel] = res.force_N
            point[sel] = res.point_m
            condition[sel] = res.condition
            reason[sel] = res.reason
        self.samples += T
        self.contact_samples += int(contact.sum())
        self.reason_counts += np.bincount(reason[contact], minlength=len(loc_mod.REASONS))
        breaks = None
        if self.episode_stage is not None:       # episode estimates and bounds (estimator.intervals)
            breaks = self.episode_stage.feed(rec, t, q, r_obs, contact, link, alpha, force,
                                             rec["q_loc"], rec["since_s"])
        self.episodes.feed(rec["g0"], t, contact, link, alpha, force[:, 0], force[:, 1],
                           point[:, 0], point[:, 1], rec["q_loc"], r.T, rec["G"], breaks)
        self._close_episodes()
        return ContactEstimate(t=t, contact=contact, link=link, alpha=alpha, Fx=force[:, 0],
                               Fz=force[:, 1], px=point[:, 0], pz=point[:, 1], rnorm=rec["rnorm"],
                               condition=condition, reason=reason, residual=r_obs, method=self.method,
                               expected_force_N=expected_force)

    def _tally_misfit(self, t_s, res) -> None:
        """The whitened fits' χ² (estimator.misfit) of the well-localized samples."""
        from estimator.misfit import MisfitTally

        if self.misfit is None:
            self.misfit = MisfitTally(dof=self.n - 3)
        ok = res.reason == loc_mod.OK
        self.misfit.add(t_s[ok], res.cost[ok])

    def misfit_warning(self, src: str) -> str | None:
        """A warning when one contact does not explain the residual (estimator.misfit)."""
        return None if self.misfit is None else self.misfit.warning(src)

    def _close_episodes(self):
        eps = self.episodes.closed
        if not eps:
            return
        self.episodes.closed = []
        rows = [EpisodeAccumulator.summary(ep) for ep in eps]
        if self.method == "dynamic" and self.Rm is not None and not self.expected:
            reps = [EpisodeAccumulator.representative(ep) for ep in eps]
            R = self.Rm
            if getattr(self, "model_term", None) is not None:    # noise + model term there
                R = np.stack([self.Rm_noise + g @ g.T for _, _, g in reps])
            errs = episode_errors(self.robot, np.stack([a for a, _, _ in reps]),
                                   np.stack([b for _, b, _ in reps]), R, self.loc_kwargs)
            for row, err in zip(rows, errs):
                row.update(err)
        model_sd = None
        if self.method == "dynamic" and self.Rm is not None and not self.expected \
                and getattr(self, "model_term", None) is not None and self.episode_stage is not None:
            # the model error is systematic: it does not average down over an episode, so its
            # per-sample part J G Gᵀ Jᵀ (at the representative sample) adds to the episode's 1σ
            model_sd = episode_errors(self.robot, np.stack([a for a, _, _ in reps]),
                                       np.stack([b for _, b, _ in reps]),
                                       R, self.loc_kwargs,
                                       R_propagated=np.stack([g @ g.T for _, _, g in reps]))
        if self.episode_stage is not None:
            for i, row in enumerate(rows):
                # the mean force's 1σ from the per-sample one (noise averages down; a model term does not)
                row.update(self.episode_stage.fields(row["link"], row["well_conditioned_fraction"] > 0,
                                                     row if model_sd is None else None))
                if model_sd is not None:
                    add_model_error(row, model_sd[i])
        self.intervals.extend(rows)

    # ------------------------------------------------------------------ driving
    def _drain(self, final: bool) -> list:
        if self.stats is None:
            if not final and self.g < self.stats_samples:
                return []
            self._freeze_stats()
        out = [self._stage2(rec) for rec in self.queue]
        self.queue = []
        return out

    def feed(self, log) -> list:
        """Run a chunk (a SensorLog of consecutive samples); returns the parts now ready.

        A long chunk is worked through in pieces of ``WORK_SAMPLES`` (cache-sized; the numbers
        do not depend on it)."""
        T, W = len(log.t), WORK_SAMPLES
        tau = log.tau_meas
        for s in range(0, T, W):
            sl = slice(s, s + W)
            rows = self.obs.feed(log.t[sl], log.q[sl], log.dq[sl], tau[sl])
            if rows is not None:
                self.queue.append(self._stage1(rows))
        return self._drain(False)

    def finish(self) -> list:
        """Flush the held rows and the open episode; returns the last parts."""
        rows = self.obs.feed(np.zeros(0), np.zeros((0, self.n)), np.zeros((0, self.n)),
                             np.zeros((0, self.n)), final=True)
        if rows is not None:
            self.queue.append(self._stage1(rows))
        out = self._drain(True)
        self.episodes.finish()
        if self.episode_stage is not None:
            self.episode_stage.finish()
        self._close_episodes()
        return out

    def summary(self) -> dict:
        names = loc_mod.REASONS
        flags = {names[k]: int(v) for k, v in enumerate(self.reason_counts) if v}
        return {"method": self.method, "samples": int(self.samples),
                "contact_samples": int(self.contact_samples), "flags_during_contact": flags,
                "intervals": list(self.intervals), **self.info,
                **({"misfit": self.misfit.summary()} if self.misfit is not None else {})}
