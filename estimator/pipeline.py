"""The whole estimator on a log: observer → detection → isolation/localization, per sample.

``estimate(robot, log, method="dynamic", gain_per_s=100.0, threshold=None, ...)`` returns a
``ContactEstimate`` with one entry per log sample (see its fields). Methods (estimator.localization):
``dynamic`` (observer residual on all rows, least squares per link; default) and ``paper``
(eqs. 6–9, quasi-static). Detection (on the observer residual minus the part explained by the
expected contacts): for ``dynamic`` a chi-square test on the residual whitened by its no-contact
covariance (estimator.noise) at a stated false-alarm rate; for ``paper`` or a given ``threshold``
the paper's ‖r‖ > ε_res; optional debounce. The force channels' sampling (estimator.timing) sets
the observer's quadrature.

One code path, in bounded memory: ``EstimatorStream`` takes a log chunk by chunk (any chunk
sizes give the same per-sample numbers, bit for bit) and carries everything that spans a chunk
boundary in its state: the observer (last row's r, P, u, τ), the rows a group delay reads ahead,
the past postures for the lag compensation, the detector's state (``DetectorState``: debounce run),
the open contact episode's running sums. ``estimate()`` is the one-chunk case.

Hooks of the localization limit: the chi-square detector's contacts end at their release
(estimator.release); the fit reads the observer restarted at each onset (estimator.onset),
weighted by R⁻¹; each interval's point, ± and Cramér–Rao bounds come from its episode
(estimator.intervals: the episode estimate, slides split an episode).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field

import numpy as np

from estimator import detection, kernels, localization as loc_mod, observer
from estimator import noise as noise_mod
from estimator import intervals, onset, release
from estimator import sequential
from estimator import timing as timing_mod
from estimator.errors import InputError
from estimator.log import SensorLog
from estimator.robot import Robot

METHODS = ("dynamic", "paper")
DEFAULT_FALSE_ALARM_RATE = (1.0, "h")
FRAME_COLUMNS = ["t", "contact", "link", "alpha", "Fx", "Fz", "px", "pz", "rnorm"]


@dataclass
class ContactEstimate:
    """Per-sample arrays (T,) unless noted. link is 1-based, 0 = no contact; F ON the robot."""

    t: np.ndarray
    contact: np.ndarray         # bool: unexpected contact detected
    link: np.ndarray            # int
    alpha: np.ndarray           # NaN when no contact or ill-conditioned (see reason)
    Fx: np.ndarray
    Fz: np.ndarray
    px: np.ndarray
    pz: np.ndarray
    rnorm: np.ndarray           # ‖r‖ (of the unexpected part) compared with the threshold
    condition: np.ndarray       # 1/|sin∠(F, link)|, NaN without contact
    reason: np.ndarray          # int8 index into estimator.localization.REASONS
    residual: np.ndarray        # (T, n) observer residual r ≈ τ_ext, floating coordinates
    method: str = "dynamic"
    expected_force_N: np.ndarray | None = None     # (T, m, 2) at the expected contacts
    n_skipped: int = 0          # log rows skipped for NaN/inf fields
    info: dict = field(default_factory=dict)
    interval_list: list | None = None   # contact intervals (``EpisodeSummary``), with error estimates

    def reason_names(self) -> np.ndarray:
        return np.asarray(loc_mod.REASONS, dtype=object)[self.reason]

    def to_frame(self):
        """pandas DataFrame ``t,contact,link,alpha,Fx,Fz,px,pz,rnorm`` (contact as 0/1)."""
        import pandas as pd

        return pd.DataFrame({"t": self.t, "contact": self.contact.astype(int), "link": self.link,
                             "alpha": self.alpha, "Fx": self.Fx, "Fz": self.Fz, "px": self.px,
                             "pz": self.pz, "rnorm": self.rnorm}, columns=FRAME_COLUMNS)

    def intervals(self) -> list[dict]:
        """Contact intervals: start/end time, samples, the most frequent link, mean α, F, p over
        the samples with a well-conditioned answer on that link (NaN if none), and the 1σ error
        estimates (``EpisodeSummary``)."""
        return list(self.interval_list or [])

    def summary(self) -> dict:
        reasons = self.reason_names()[self.contact]
        names, counts = np.unique(reasons, return_counts=True) if reasons.size else ([], [])
        return {"method": self.method, "samples": int(len(self.t)), "skipped_samples": self.n_skipped,
                "contact_samples": int(self.contact.sum()),
                "flags_during_contact": {str(k): int(v) for k, v in zip(names, counts)},
                "intervals": self.intervals(), **self.info}


def _expected(robot: Robot, expected_contacts):
    if expected_contacts is None or expected_contacts is False or len(expected_contacts) == 0:
        return ()
    if isinstance(expected_contacts, str):
        if expected_contacts != "foot":
            raise InputError(f"expected contacts: unknown {expected_contacts!r}; use 'foot' or "
                             f"a list of (link, alpha)")
        return ((robot.n_links, 1.0),)
    return tuple((int(k), float(a)) for k, a in expected_contacts)


STATS_SAMPLES = 65536           # the noise floors come from the contact-free samples among these
WORK_SAMPLES = 16384            # samples per piece of work inside a chunk (cache-sized)


@dataclass
class DetectorState:
    """What a detector carries from one chunk to the next: the debounce run (samples in a row
    above the threshold, up to the last one seen), and room for a sequential test's state."""

    run: int = 0
    extra: dict = field(default_factory=dict)


def debounce_chunk(raw: np.ndarray, debounce: int, state: DetectorState) -> np.ndarray:
    """contact[k] = raw for the ``debounce`` + 1 samples k−debounce…k (all of them), counted
    across chunk boundaries through ``state.run`` (updated): the rule of ``detection.detect``."""
    raw = np.asarray(raw, bool)
    if raw.size == 0:
        return raw
    idx = np.arange(raw.size)
    last_false = np.maximum.accumulate(np.where(raw, -1, idx))
    run = np.where(last_false >= 0, idx - last_false, state.run + idx + 1)
    state.run = int(run[-1])
    return run >= debounce + 1


def _chi2_isf(alpha: float, dof: int) -> float:
    """h with P(χ²_dof > h) = α: scipy.special.chdtri, what scipy.stats.chi2.isf evaluates (and
    noise.chi2_threshold), without importing scipy.stats (seconds at start-up)."""
    from scipy.special import chdtri

    return float(chdtri(dof, alpha))


def _sumsq_rows(xT: np.ndarray) -> np.ndarray:
    """Σ_k x_k² per sample of a link-major (n, T) array, rows added in order (batch-independent)."""
    out = xT[0] * xT[0]
    for k in range(1, len(xT)):
        out += xT[k] * xT[k]
    return out


def _whitened(rT: np.ndarray, Linv: np.ndarray) -> np.ndarray:
    """s_k = ‖L⁻¹ r_k‖², with one lower-triangular L⁻¹ (n, n) or one per sample (T, n, n)."""
    n = rT.shape[0]
    out = np.zeros(rT.shape[1])
    for i in range(n):
        z = None
        for j in range(i + 1):
            c = Linv[i, j] if Linv.ndim == 2 else Linv[:, i, j]
            z = c * rT[j] if z is None else z + c * rT[j]
        out += z * z
    return out


def _fit_weights(rec, sel, T: int, n: int, row_weights):
    """The localization's weights for the selected samples: W = L⁻ᵀL⁻¹ = R⁻¹ from the detector's
    whitening blocks (the maximum-likelihood fit; the noise covariance R is the detector's, per
    posture block), else the diagonal ``row_weights`` (the paper rule: no noise model)."""
    if rec.get("Linv") is None:
        return loc_mod.weight_blocks(n, T, row_weights)[0], \
            np.zeros(T, np.int64)[sel]
    Linv, idx = rec["Linv"]
    return np.einsum("bki,bkj->bij", Linv, Linv), idx[sel]


ERROR_METHOD = ("first-order propagation of the residual's no-contact covariance through the "
                "least-squares localization at one sample of the episode (the kept sample 2^j − 1 "
                "samples after its start nearest below its middle), 1σ per sample")


def _episode_errors(robot, q_rows, r_rows, R, loc_kwargs, h=1e-4, R_propagated=None):
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


def _add_model_error(row: dict, model: dict):
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


class _ObserverRun:
    """The observer over a log fed in chunks: ``feed(log, final)`` → the finalized rows as a dict
    (t, q, dq, tau (T, n), r (T, n)); rows a group delay still needs the future of are held back
    (``observer.lookahead_rows``) until the next chunk or ``final``."""

    def __init__(self, robot, K, dt, method, timing):
        self.robot, self.K, self.dt, self.method, self.timing = robot, K, dt, method, timing
        self.ahead = observer.lookahead_rows(timing, dt)
        self.prev = None                 # (t, P, u, τ, r) of the last finalized row (link-major rows)
        self.pending = None              # held-back raw rows: (t, q, dq, τ)

    def feed(self, t, q, dq, tau, final: bool = False):
        if self.pending is not None:
            pt, pq, pdq, ptau = self.pending
            t, q, dq, tau = np.r_[pt, t], np.vstack([pq, q]), np.vstack([pdq, dq]), np.vstack([ptau, tau])
            self.pending = None
        T = len(t)
        keep = 0 if final else min(self.ahead, T)
        if T == 0 or T - keep == 0:
            self.pending = (t, q, dq, tau) if T else None
            return None
        P, u = observer.momentum_terms(self.robot, q, dq, tau)
        PT, uT, tauT = P.T, u.T, tau.T
        if self.prev is not None:
            t0, P0, u0, tau0, r0 = self.prev
            tw = np.r_[t0, t]
            PT, uT, tauT = (np.concatenate([x0[:, None], x], axis=1) for x0, x in
                            ((P0, PT), (u0, uT), (tau0, tauT)))
        else:
            tw, r0 = t, np.zeros(self.K.size)
        rT = observer.residual_window(tw, np.ascontiguousarray(PT), np.ascontiguousarray(uT),
                                      tauT, self.K, self.dt, self.method, self.timing, r0)
        off = 1 if self.prev is not None else 0
        m = T - keep                                            # rows finalized now
        last = off + m - 1
        self.prev = (tw[last], PT[:, last].copy(), uT[:, last].copy(), tauT[:, last].copy(),
                     rT[:, last].copy())
        if keep:
            self.pending = (t[m:], q[m:], dq[m:], tau[m:])
        return {"t": t[:m], "q": q[:m], "dq": dq[:m], "tau": tau[:m],
                "rT": rT[:, off:off + m]}


class _EpisodeAccumulator:
    """Contact intervals merged across chunk boundaries from running sums (bounded memory).

    Per interval: the most frequent link, and over its samples on that link with a finite α the
    means of α, p, over those with a finite F the mean F (sums in sample order), the
    well-conditioned fraction; the representative sample for the error estimate is kept from
    the samples 2^j − 1 after the start (O(log L) rows)."""

    KEYS = ("alpha", "px", "pz", "Fx", "Fz")

    def __init__(self, n_links: int):
        self.nb = n_links + 1
        self.open = None
        self.closed = []                 # finished episodes waiting for their error estimate

    def _new(self, g, t):
        return {"g0": g, "t0": t, "t1": t, "n": 0, "counts": np.zeros(self.nb),
                "good": np.zeros(self.nb), "same": np.zeros(self.nb),
                "sums": {k: np.zeros(self.nb) for k in self.KEYS}, "kept": []}

    def feed(self, g0, t, contact, link, alpha, Fx, Fz, px, pz, q_loc, rT, G=None, breaks=None):
        """``G`` (T, n, c): the model term's factor per sample (None without one); ``breaks`` (T,)
        bool: a new interval starts at this contact sample (a slide)."""
        c = contact.astype(np.int8)
        if breaks is not None and len(c) and breaks[0] and self.open is not None:
            self.closed.append(self.open)
            self.open = None
        prev = 1 if self.open is not None else 0
        edges = np.diff(np.concatenate([[prev], c, [0]]))
        starts = np.flatnonzero(edges == 1)
        stops = np.flatnonzero(edges == -1)
        if prev:
            starts = np.r_[0, starts]
        if breaks is not None:
            cut = np.flatnonzero(np.asarray(breaks, bool) & contact.astype(bool))
            cut = cut[cut > 0]
            starts = np.sort(np.r_[starts, cut])
            stops = np.sort(np.r_[stops, cut])
        if not starts.size:
            return
        # segment id per sample (valid where contact): index of the start at or before it
        sid = np.searchsorted(starts, np.arange(len(c)), side="right") - 1
        on = np.flatnonzero(c)
        S = len(starts)
        key = sid[on] * self.nb + link[on]
        size = S * self.nb
        counts = np.bincount(key, minlength=size).reshape(S, self.nb)
        good = np.isfinite(alpha[on])
        same = np.isfinite(Fx[on])
        gcount = np.bincount(key[good], minlength=size).reshape(S, self.nb)
        scount = np.bincount(key[same], minlength=size).reshape(S, self.nb)
        sums = {}
        for k, x, m in (("alpha", alpha, good), ("px", px, good), ("pz", pz, good),
                        ("Fx", Fx, same), ("Fz", Fz, same)):
            sums[k] = np.bincount(key[m], weights=x[on][m], minlength=size).reshape(S, self.nb)
        for i in range(S):
            a, b = int(starts[i]), int(stops[i])
            if i == 0 and prev:
                ep = self.open
            else:
                ep = self._new(g0 + a, float(t[a]))
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
            if b < len(c):
                self.closed.append(ep)
                self.open = None
            else:
                self.open = ep

    def close_all(self):
        if self.open is not None:
            self.closed.append(self.open)
            self.open = None

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
      nearest below its middle (``_EpisodeAccumulator``), not its exact middle (which needs the
      episode's end); its point and ± (estimator.intervals) are sums over all its samples.
    """

    def __init__(self, robot: Robot, method: str = "dynamic", gain_per_s=100.0,
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
        self.obs = _ObserverRun(robot, self.K, self.dt, discretization, timing)
        self.state = DetectorState()
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
            self.h = _chi2_isf(alpha, self.n)
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
        self.episodes = _EpisodeAccumulator(robot.n_links)
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
            return np.sqrt(_sumsq_rows(unexpT)), None
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
                return _whitened(unexpT, self.Linv), None
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
        return _whitened(unexpT, L_all[idx]), None

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
                self.cusum_cal = sequential.model_calibration(self.robot, q0, dq0, self.noise,
                                                              self.gain_per_s, self.dt, self.timing)
            if "cusum_threshold" not in self.info:
                h = self.cusum_cal.threshold(self.alpha)
                self.info = sequential.detector_info(self.info, h, self.cusum_cal)
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
            if n_sel and not self.expected and kernels.available():
                # one compiled pass: the fit at q(t − lag), the point at the current posture
                out = kernels.localize_dynamic(self.full, rec["q_loc"][sel], r[sel], weight, q[sel],
                                               position_tol_m=0.005, bound_tol=0.05, **kw)
                res = loc_mod.Localization(*out[:6], cost=out[6])
                fused = True
            elif n_sel:
                res = loc_mod.localize_dynamic(self.robot, rec["q_loc"][sel], r[sel],
                                               expected=self.expected, weight=weight, **kw)
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

    def _close_episodes(self):
        eps = self.episodes.closed
        if not eps:
            return
        self.episodes.closed = []
        rows = [_EpisodeAccumulator.summary(ep) for ep in eps]
        if self.method == "dynamic" and self.Rm is not None and not self.expected:
            reps = [_EpisodeAccumulator.representative(ep) for ep in eps]
            R = self.Rm
            if getattr(self, "model_term", None) is not None:    # noise + model term there
                R = np.stack([self.Rm_noise + g @ g.T for _, _, g in reps])
            errs = _episode_errors(self.robot, np.stack([a for a, _, _ in reps]),
                                   np.stack([b for _, b, _ in reps]), R, self.loc_kwargs)
            for row, err in zip(rows, errs):
                row.update(err)
        model_sd = None
        if self.method == "dynamic" and self.Rm is not None and not self.expected \
                and getattr(self, "model_term", None) is not None and self.episode_stage is not None:
            # the model error is systematic: it does not average down over an episode, so its
            # per-sample part J G Gᵀ Jᵀ (at the representative sample) adds to the episode's 1σ
            model_sd = _episode_errors(self.robot, np.stack([a for a, _, _ in reps]),
                                       np.stack([b for _, b, _ in reps]),
                                       R, self.loc_kwargs,
                                       R_propagated=np.stack([g @ g.T for _, _, g in reps]))
        if self.episode_stage is not None:
            for i, row in enumerate(rows):
                # the mean force's 1σ from the per-sample one (noise averages down; a model term does not)
                row.update(self.episode_stage.fields(row["link"], row["well_conditioned_fraction"] > 0,
                                                     row if model_sd is None else None))
                if model_sd is not None:
                    _add_model_error(row, model_sd[i])
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

    def feed(self, log: SensorLog) -> list:
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
        self.episodes.close_all()
        if self.episode_stage is not None:
            self.episode_stage.finish()
        self._close_episodes()
        return out

    def summary(self) -> dict:
        names = loc_mod.REASONS
        flags = {names[k]: int(v) for k, v in enumerate(self.reason_counts) if v}
        return {"method": self.method, "samples": int(self.samples),
                "contact_samples": int(self.contact_samples), "flags_during_contact": flags,
                "intervals": list(self.intervals), **self.info}


def _resolve_timing(robot, log, timing):
    if timing is None:
        timing = getattr(log, "timing", None)
        source = "log declaration" if timing is not None else "default (instantaneous)"
    else:
        source = "option"
    if isinstance(timing, str):
        timing = timing_mod.uniform(timing, robot.n_links)
    return timing, source


def quiet_window_covariance(robot, chunks, window, gain_per_s, period_s, discretization="exact",
                            timing=None, where: str = "--quiet-window", model_cov=None,
                            model_source: str = "", alpha: float | None = None):
    """(R, r): the residual's sensor-noise covariance read from the contact-free window (t0, t1)
    (noise.quiet_covariance: the innovations, not the spread of r, which also holds the model
    error) and the window's residual rows, from an observer-only pass over the log's chunks
    (stops after t1): the first of two passes. ``where`` names the window in errors.

    The window must then be explained by that noise and the model term (``model_cov``, Σ_θ): the
    median of s_k = r_kᵀ (R + Φ_k Σ_θ Φ_kᵀ)⁻¹ r_k over it must be that of χ²_n within its sampling
    error; otherwise its residual is model error that the stated uncertainty does not cover (on a
    moving leg it is not stationary, so no covariance of the stretch could stand for it), and
    the window is refused naming what to do."""
    t0, t1 = window
    K = observer.gains(robot, gain_per_s)
    n = K.size
    run = _ObserverRun(robot, K, float(period_s), discretization, timing)
    term = None
    if model_cov is not None:                     # Φ from the log's start, kept on the window
        from estimator.model_error import ModelTerm

        term = ModelTerm(observer.full_robot(robot), model_cov, gain_per_s, float(period_s),
                         discretization)
    ts, rs, Gs = [], [], []
    empty = np.zeros((0, n))
    for chunk in itertools.chain(chunks, [None]):        # lazily: stop after t1
        final = chunk is None
        rows = run.feed(np.zeros(0), empty, empty, empty, final=True) if final else \
            run.feed(chunk.t, chunk.q, chunk.dq, chunk.tau_meas)
        if rows is not None:
            keep = (rows["t"] >= t0) & (rows["t"] <= t1)
            ts.append(rows["t"][keep])
            rs.append(rows["rT"].T[keep])
            if term is not None:
                m = len(rows["t"])
                _, G = term.statistic(rows["t"], rows["q"], rows["dq"], rows["rT"],
                                      np.eye(n)[None], np.zeros(m, np.int64))
                Gs.append(G[keep])
            if rows["t"][-1] > t1:
                break
    t = np.concatenate(ts) if ts else np.zeros(0)
    r = np.concatenate(rs) if rs else empty
    R = noise_mod.quiet_covariance(r, t, t0, t1, gain_per_s, float(period_s), where, discretization)
    if term is not None:
        from estimator.model_error import statistic_numpy

        stat = statistic_numpy(r.T, np.concatenate(Gs), R[None], np.zeros(len(t), np.int64))
    else:
        stat = _whitened(np.ascontiguousarray(r.T), np.linalg.inv(np.linalg.cholesky(R)))
    a = float(np.exp(-np.min(K) * float(period_s)))
    n_eff = max(1.0, len(t) * (1 - a) / (1 + a))
    ratio = float(np.median(stat)) / _chi2_isf(0.5, n)
    tol = max(0.5, 6.0 * np.sqrt(2.0 / (n * n_eff)))
    if ratio > 1.0 + tol:
        cover = (f"the model uncertainty ({model_source}) does not cover it" if model_cov is not None
                 else "the robot file states no model uncertainty")
        raise InputError(f"{where}: the residual over {t0:g}–{t1:g} s is {np.sqrt(ratio):.2g}× what "
                         f"its sensor noise explains: a contact held through the stretch, or model "
                         f"error and {cover}; mark a stretch without contact, or identify the robot "
                         f"(torquebench identify) or declare its model uncertainty "
                         f"(--model-uncertainty, a [model_uncertainty] table)")
    return R, r


def estimate(robot: Robot, log: SensorLog, method: str = "dynamic", gain_per_s=100.0,
             threshold: float | None = None, debounce: int = 0, expected_contacts=None, *,
             discretization: str = "exact", row_weights=None, min_force_N: float = 0.05,
             max_condition: float = 20.0, isolation_floor: float = 0.01,
             lag_compensation: bool = True, timing=None, noise=None, quiet_window=None,
             false_alarm_rate=DEFAULT_FALSE_ALARM_RATE, cov_stride_s: float = 0.01,
             stats_samples: int = STATS_SAMPLES, chunk_samples: int | None = None,
             detector: str = "chi2", quiet_where: str = "--quiet-window",
             model_uncertainty=None, release_test: bool = True,
             onset_restart: bool = True) -> ContactEstimate:
    """Run observer, detection and localization on a whole log (offline, vectorized).

    ``EstimatorStream`` on the log in one chunk (or in chunks of ``chunk_samples``: the same
    numbers); see it for the rules of the noise floors and the error estimates.

    expected_contacts: None (→ ``log.expected_contacts``), ``"foot"`` (last link, α = 1) or
    [(link, α), …]: contacts the robot expects; their forces are estimated jointly and never
    reported as a collision. ``False`` or ``()`` forces none.

    Localization (``dynamic``): the fit is weighted by R⁻¹, the detector's noise covariance (the
    maximum-likelihood fit; the paper rule's ``threshold`` has no R: unweighted), on the
    observer restarted at each contact's onset (estimator.onset). Each interval's point and ±
    come from its episode estimate, with the Cramér–Rao bounds beside them (estimator.intervals).

    Flags (estimator.localization): |F| below max(min_force_N, 5 σ of the force rows without
    contact) → small_force; two links fitting within 2√n noise norms (R known; else max(1e-3,
    2 · median ‖r‖ without contact)) at points > 5 mm apart → ambiguous_link; 1/|sin∠(F, link)| >
    max_condition → parallel_to_link. (σ and the median: over the contact-free samples among the
    first ``stats_samples``.)

    lag_compensation (``dynamic`` only): r lags τ_ext by ≈ 1/K (``observer.lag_s``), so r_k is
    paired with the posture q(t_k − lag) (linear interpolation in time, held at q(t_0) before
    the start) to solve for (F, α); α is a body coordinate, so the reported point is
    p_c + α Δ_c at the CURRENT posture.

    timing: per force channel [(kind, delay_s)] or one 'instant' | 'mean' | 'delay:SECONDS' for
    all (estimator.timing); None → what the log declares (``log.timing``), else instantaneous.

    Detection: ``method="paper"`` or a given ``threshold`` → ‖r‖ > ε (ε = 0.06 by default, the
    paper's rule). Otherwise (``dynamic``) the chi-square test on the residual whitened by its
    no-contact covariance (estimator.noise) from ``noise`` (a NoiseModel; default the paper leg's
    sensors) or from the ``quiet_window`` (t0, t1) of the log, at ``false_alarm_rate`` = (value,
    unit) with unit 'sample', 's' or 'h' (default one per hour); ``rnorm`` is then √(rᵀR⁻¹r).
    ``detector="cusum"``: a CUSUM on the same statistic (estimator.sequential) instead. With the
    chi-square test (and no debounce) a contact ends at its release (estimator.release;
    ``release_test=False``: when ‖r‖ has decayed under the threshold, as before;
    ``onset_restart=False``: localize on the running observer, not the one restarted at the onset). ``paper``
    isolates on rows whitened by the noise model (detection.whitened_thresholds) at the per-row
    probability of ``false_alarm_rate``; with a ``quiet_window``, on the robust σ of the stretch.

    Model uncertainty (``dynamic`` chi-square only; estimator.model_error): the residual's
    covariance gains R_model,k = Φ_k Σ_θ Φ_kᵀ per sample. ``model_uncertainty``: None → what the
    robot file states (its identification's covariance, else its [model_uncertainty]); a
    ``ModelUncertainty`` or a Σ_θ array → that; False → none.
    """
    if log.n_links != robot.n_links:
        raise InputError(f"{getattr(log, 'source', 'log')}: {log.n_links} joints in the log but the "
                         f"robot '{robot.name}' has {robot.n_links} links")
    stream = open_stream(robot, log, method, gain_per_s, threshold, debounce, expected_contacts,
                         discretization=discretization, row_weights=row_weights,
                         min_force_N=min_force_N, max_condition=max_condition,
                         isolation_floor=isolation_floor, lag_compensation=lag_compensation,
                         timing=timing, noise=noise, quiet_window=quiet_window,
                         quiet_chunks=lambda: [log], quiet_where=quiet_where,
                         false_alarm_rate=false_alarm_rate,
                         cov_stride_s=cov_stride_s, stats_samples=stats_samples, detector=detector,
                         model_uncertainty=model_uncertainty, release_test=release_test,
                         onset_restart=onset_restart)
    T = len(log.t)
    step = T if not chunk_samples else int(chunk_samples)
    parts = []
    for s in range(0, T, max(step, 1)):
        parts += stream.feed(_slice_log(log, slice(s, s + step)))
    parts += stream.finish()
    return join_parts(parts, stream, n_skipped=getattr(log, "n_skipped", 0))


def _slice_log(log: SensorLog, sl) -> SensorLog:
    return SensorLog(t=log.t[sl], q=log.q[sl], dq=log.dq[sl], tau_Nm=log.tau_Nm[sl],
                     wrench=log.wrench[sl], floating=log.floating, source=log.source)


def open_stream(robot, log, method="dynamic", gain_per_s=100.0, threshold=None, debounce=0,
                expected_contacts=None, *, timing=None, quiet_window=None, quiet_chunks=None,
                quiet_where: str = "--quiet-window", period_s=None, model_uncertainty=None,
                **kw) -> EstimatorStream:
    """An EstimatorStream set up for ``log`` (its first chunk, or a LogReader: the expected
    contacts, timing declaration and period come from it). ``quiet_chunks()``: a fresh iterable
    of the log's chunks for the quiet-window pass."""
    if method not in METHODS:
        raise InputError(f"method: unknown {method!r}; use one of {', '.join(METHODS)}")
    if expected_contacts is None:
        expected_contacts = getattr(log, "expected_contacts", ()) or None
    expected = _expected(robot, expected_contacts)
    timing, timing_source = _resolve_timing(robot, log, timing)
    if period_s is None:
        period_s = getattr(log, "period_s", None) or observer.regular_period(log.t)
    cov, cov_source, cal, drive = None, "", None, None
    model_cov, model_source = None, ""
    if method == "dynamic" and threshold is None:
        from estimator.model_error import resolve

        model_cov, model_source = resolve(robot, model_uncertainty)
    elif model_uncertainty not in (None, False):
        raise InputError("model uncertainty: enters the chi-square detector of the dynamic method; "
                         "not with --method paper or --threshold")
    if quiet_window is not None and method == "dynamic" and threshold is None:
        cov, r_quiet = quiet_window_covariance(robot, quiet_chunks(), quiet_window, gain_per_s,
                                               period_s, kw.get("discretization", "exact"), timing,
                                               quiet_where, model_cov, model_source)
        from estimator.bounds import sample_terms      # the drive's noise for the episode estimate

        drive = sample_terms(r_quiet, cov, np.exp(-observer.gains(robot, gain_per_s) * period_s))
        cov_source = (f"robust estimate over the quiet window {quiet_window[0]:g}–"
                      f"{quiet_window[1]:g} s (sensor noise from the observer's innovations)")
        if kw.get("detector") == "cusum":         # CUSUM calibrated on the stretch's correlation
            z = np.linalg.solve(np.linalg.cholesky(cov), r_quiet.T).T
            a = float(np.exp(-np.min(observer.gains(robot, gain_per_s)) * period_s))
            cal = sequential.calibrate_quiet(z, a)
    return EstimatorStream(robot, method, gain_per_s, threshold, debounce, expected,
                           period_s=period_s, timing=timing, timing_source=timing_source,
                           residual_cov=cov, residual_cov_source=cov_source, cusum_calibration=cal,
                           residual_drive=drive,
                           isolation_quiet=quiet_window is not None and method == "paper",
                           model_cov=model_cov, model_cov_source=model_source, **kw)


def join_parts(parts: list, stream: EstimatorStream, n_skipped: int = 0) -> ContactEstimate:
    """One ContactEstimate from a stream's parts (in order) and its summaries."""
    n = stream.n
    cat = (lambda f, shape: np.concatenate([getattr(p, f) for p in parts]) if parts
           else np.zeros(shape))
    ef = None
    if stream.expected:
        ef = np.concatenate([p.expected_force_N for p in parts]) if parts else \
            np.zeros((0, len(stream.expected), 2))
    info = dict(stream.info)
    return ContactEstimate(t=cat("t", 0), contact=cat("contact", 0).astype(bool),
                           link=cat("link", 0).astype(int), alpha=cat("alpha", 0), Fx=cat("Fx", 0),
                           Fz=cat("Fz", 0), px=cat("px", 0), pz=cat("pz", 0), rnorm=cat("rnorm", 0),
                           condition=cat("condition", 0), reason=cat("reason", 0).astype(np.int8),
                           residual=cat("residual", (0, n)), method=stream.method,
                           expected_force_N=ef, n_skipped=n_skipped, info=info,
                           interval_list=list(stream.intervals))
