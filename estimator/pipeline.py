"""The whole estimator on a log: observer → detection → isolation/localization, per sample.

``estimate(robot, log, method="dynamic", gain_per_s=100.0, threshold=None, ...)`` returns a
``ContactEstimate`` with one entry per log sample (see its fields). Methods (estimator.localization):
``dynamic`` (observer residual on all rows, least squares per link; default) and ``paper``
(eqs. 6–9, quasi-static). Detection (on the observer residual minus the part explained by the
expected contacts): for ``dynamic`` a chi-square test on the residual whitened by its no-contact
covariance (estimator.noise) at a stated false-alarm rate; for ``paper`` or a given ``threshold``
the paper's ‖r‖ > ε_res; optional debounce. The force channels' sampling (estimator.timing) sets
the observer's quadrature.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from estimator import detection, localization as loc_mod, observer
from estimator import noise as noise_mod
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
    interval_errors: list | None = None   # per interval: predicted 1σ of α, F, p (see _episode_errors)

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
        the samples with a well-conditioned answer on that link (NaN if none)."""
        c = self.contact.astype(np.int8)
        edges = np.diff(np.concatenate([[0], c, [0]]))
        starts, stops = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
        out = []
        for i, (a, b) in enumerate(zip(starts, stops)):
            links = self.link[a:b]
            known = links[links > 0]
            link = int(np.bincount(known).argmax()) if known.size else 0
            good = (links == link) & np.isfinite(self.alpha[a:b])
            mean = (lambda x: float(np.mean(x[a:b][good])) if good.any() else float("nan"))
            same = (links == link) & np.isfinite(self.Fx[a:b])
            fmean = (lambda x: float(np.mean(x[a:b][same])) if same.any() else float("nan"))
            out.append({"t_start_s": float(self.t[a]), "t_end_s": float(self.t[b - 1]),
                        "samples": int(b - a), "link": link, "alpha": mean(self.alpha),
                        "Fx_N": fmean(self.Fx), "Fz_N": fmean(self.Fz),
                        "px_m": mean(self.px), "pz_m": mean(self.pz),
                        "well_conditioned_fraction": float(good.mean())})
            if self.interval_errors is not None and i < len(self.interval_errors):
                out[-1].update(self.interval_errors[i])
        return out

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


def _delayed(t: np.ndarray, q: np.ndarray, lag_s: float, dt_s: float) -> np.ndarray:
    """q(t − lag) by linear interpolation (held at q(t_0) before the start), (T, n).

    Uniform sampling: a shift by lag/Δt samples (two array passes); with gaps: ``np.interp``.
    """
    T = len(t)
    steps = np.diff(t)
    if np.all(np.abs(steps - dt_s) <= 0.01 * dt_s):
        shift = lag_s / dt_s
        i0 = int(np.floor(shift))
        frac = shift - i0
        def shifted(k):                               # q[max(i − k, 0)] by slicing
            out = np.empty_like(q)
            k = min(k, T)
            out[:k] = q[0]
            out[k:] = q[:T - k]
            return out

        a = shifted(i0)
        b = shifted(i0 + 1)
        b -= a
        b *= frac
        b += a
        return b
    return np.stack([np.interp(t - lag_s, t, q[:, k]) for k in range(q.shape[1])], axis=-1)


def _noise_detector(robot, log, r, unexp, gain_per_s, timing, noise, quiet_window,
                    false_alarm_rate, cov_stride_s):
    """(contact, statistic, info) of the chi-square detector (estimator.noise)."""
    T = len(log.t)
    dt = observer.regular_period(log.t)
    value, unit = false_alarm_rate if isinstance(false_alarm_rate, tuple) else (false_alarm_rate, "s")
    alpha = noise_mod.per_sample_rate(value, unit, dt)
    n = r.shape[1]
    h = noise_mod.chi2_threshold(alpha, n)
    if quiet_window is not None:
        R = noise_mod.quiet_covariance(r, log.t, *quiet_window, gain_per_s, dt)
        stride, source = None, (f"robust estimate over the quiet window {quiet_window[0]:g}–"
                                f"{quiet_window[1]:g} s")
    else:
        noise = noise_mod.paper_leg_noise() if noise is None else noise
        if noise.velocity_sigma_rad_per_s == 0 and noise.encoder_counts == 0:
            R, stride = noise_mod.residual_covariance(robot, log.q[:1], log.dq[:1], noise, gain_per_s,
                                                      dt, timing)[0], None     # posture-independent
        else:
            stride = max(1, int(round(cov_stride_s / dt)))
            R = noise_mod.residual_covariance(robot, log.q[::stride], log.dq[::stride], noise,
                                              gain_per_s, dt, timing)
        source = "sensor noise model, " + noise.describe()
    stat = noise_mod.whitened_statistic(unexp, R, stride)
    Rm = R if R.ndim == 2 else np.median(R, axis=0)
    info = {"detector": "chi-square on the whitened residual",
            "false_alarm_probability_per_sample": alpha,
            "false_alarm_rate_per_s": alpha / dt, "chi2_threshold": h, "chi2_dof": n,
            "residual_noise_source": source,
            "residual_sigma": np.sqrt(np.diag(Rm)).tolist()}
    return stat > h, stat, info, Rm


ERROR_METHOD = ("first-order propagation of the residual's no-contact covariance through the "
                "least-squares localization at the episode's middle sample, 1σ per sample")


def _episode_errors(robot, contact, q_loc_full, r, R, loc_kwargs, h=1e-4):
    """Per contact episode: 1σ of α, Fx, Fz, px, pz per sample, J R Jᵀ with J = ∂(α, F, p)/∂r
    by central differences of localize_dynamic at the episode's middle sample."""
    c = contact.astype(np.int8)
    edges = np.diff(np.concatenate([[0], c, [0]]))
    mids = (np.flatnonzero(edges == 1) + np.flatnonzero(edges == -1) - 1) // 2
    n = r.shape[1]
    out = []
    if mids.size == 0:
        return out
    eye = np.eye(n) * h
    rp = np.concatenate([r[mids][:, None] + eye, r[mids][:, None] - eye], axis=1).reshape(-1, n)
    qp = np.repeat(q_loc_full[mids], 2 * n, axis=0)
    res = loc_mod.localize_dynamic(robot, qp, rp, **loc_kwargs)
    y = np.concatenate([res.alpha[:, None], res.force_N, res.point_m], axis=1).reshape(len(mids), 2 * n, 5)
    J = (y[:, :n] - y[:, n:]) / (2 * h)                           # (E, n, 5)
    cov = np.einsum("eki,kl,elj->eij", J, R, J)
    sd = np.sqrt(np.clip(np.diagonal(cov, axis1=1, axis2=2), 0, None))
    for e in range(len(mids)):
        row = {}
        for j, key in enumerate(["alpha", "Fx_N", "Fz_N", "px_m", "pz_m"]):
            v = float(sd[e, j])
            row[f"{key}_error_estimate"] = v if np.isfinite(v) else None
            row[f"{key}_error_method"] = ERROR_METHOD if np.isfinite(v) else \
                "not available: the localization refused a perturbed answer (ill-conditioned)"
        out.append(row)
    return out


def estimate(robot: Robot, log: SensorLog, method: str = "dynamic", gain_per_s=100.0,
             threshold: float | None = None, debounce: int = 0, expected_contacts=None, *,
             discretization: str = "exact", row_weights=None, min_force_N: float = 0.05,
             max_condition: float = 20.0, isolation_floor: float = 0.01,
             lag_compensation: bool = True, timing=None, noise=None, quiet_window=None,
             false_alarm_rate=DEFAULT_FALSE_ALARM_RATE, cov_stride_s: float = 0.01,
             detector: str = "chi2") -> ContactEstimate:
    """Run observer, detection and localization on a whole log (offline, vectorized).

    expected_contacts: None (→ ``log.expected_contacts``), ``"foot"`` (last link, α = 1) or
    [(link, α), …]: contacts the robot expects; their forces are estimated jointly and never
    reported as a collision. ``False`` or ``()`` forces none.

    Flags (estimator.localization): |F| below max(min_force_N, 5 σ of the force rows without
    contact) → small_force; two links fitting within max(1e-3, 2 · median ‖r‖ without contact)
    at points > 5 mm apart → ambiguous_link; 1/|sin∠(F, link)| > max_condition → parallel_to_link.

    lag_compensation (``dynamic`` only): r lags τ_ext by ≈ 1/K (``observer.lag_s``), so r_k is
    paired with the posture q(t_k − lag) (linear interpolation) to solve for (F, α); α is a body
    coordinate, so the reported point is p_c + α Δ_c at the CURRENT posture.

    timing: per force channel [(kind, delay_s)] or one 'instant' | 'mean' | 'delay:SECONDS' for
    all (estimator.timing); None → what the log declares (``log.timing``), else instantaneous.

    Detection: ``method="paper"`` or a given ``threshold`` → ‖r‖ > ε (ε = 0.06 by default, the
    paper's rule). Otherwise (``dynamic``) the chi-square test on the residual whitened by its
    no-contact covariance (estimator.noise) from ``noise`` (a NoiseModel; default the paper leg's
    sensors) or from the ``quiet_window`` (t0, t1) of the log, at ``false_alarm_rate`` = (value,
    unit) with unit 'sample', 's' or 'h' (default one per hour); ``rnorm`` is then √(rᵀR⁻¹r).
    ``detector="cusum"``: a CUSUM on the same statistic (estimator.sequential) instead.
    """
    if method not in METHODS:
        raise InputError(f"method: unknown {method!r}; use one of {', '.join(METHODS)}")
    if detector not in ("chi2", "cusum"):
        raise InputError(f"detector: unknown {detector!r}; use chi2 or cusum")
    if log.n_links != robot.n_links:
        raise InputError(f"{getattr(log, 'source', 'log')}: {log.n_links} joints in the log but the "
                         f"robot '{robot.name}' has {robot.n_links} links")
    if expected_contacts is None:
        expected_contacts = getattr(log, "expected_contacts", ()) or None
    expected = _expected(robot, expected_contacts)
    if timing is None:
        timing = getattr(log, "timing", None)
        timing_source = "log declaration" if timing is not None else "default (instantaneous)"
    else:
        timing_source = "option"
    if isinstance(timing, str):
        timing = timing_mod.uniform(timing, robot.n_links)
    tau_meas = log.tau_meas                            # assembled once
    P, u = observer.momentum_terms(robot, log.q, log.dq, tau_meas)
    r = observer.residual_offline(robot, log.t, log.q, log.dq, tau_meas, gain_per_s,
                                  method=discretization, terms=(P, u), timing=timing)
    if expected:
        unexp, _ = loc_mod.explain_expected(robot, log.q, r, expected, row_weights)
    else:
        unexp = r
    T = len(log.t)
    det_info, R = {}, None
    if method == "paper" or threshold is not None or T < 2:
        threshold = 0.06 if threshold is None else threshold
        rnorm = np.sqrt(np.einsum("tk,tk->t", unexp, unexp))
        contact = detection.detect(rnorm, threshold, debounce)
        det_info = {"detector": "paper rule ||r|| > threshold", "threshold": threshold}
    else:
        contact, stat, det_info, R = _noise_detector(robot, log, r, unexp, gain_per_s, timing, noise,
                                                     quiet_window, false_alarm_rate, cov_stride_s)
        rnorm = np.sqrt(stat)
        if detector == "cusum":       # sequential test on the same statistic (estimator.sequential)
            from estimator import sequential
            contact, det_info, _, _ = sequential.pipeline_detector(robot, log, unexp, stat, det_info, R,
                                                                gain_per_s, timing, noise, quiet_window)
        elif debounce:
            contact = detection.detect(rnorm, float(np.sqrt(det_info["chi2_threshold"])), debounce)
    sel = np.flatnonzero(contact)
    if sel.size == T:
        sel = slice(None)                              # every sample: views, no copies
    n_sel = T if isinstance(sel, slice) else sel.size
    link = np.zeros(T, dtype=int)
    alpha = np.full(T, np.nan)
    force = np.full((T, 2), np.nan)
    point = np.full((T, 2), np.nan)
    condition = np.full(T, np.nan)
    reason = np.full(T, loc_mod.NO_CONTACT, dtype=np.int8)
    expected_force = None
    info = {"timing": timing_mod.describe(timing), "timing_source": timing_source, **det_info}
    # noise-aware floors from the samples without contact (robust σ; noise-free logs keep the floors)
    quiet = ~contact
    force_floor = float(detection.noise_thresholds(r[:, :2], quiet, floor=min_force_N).max())
    if R is not None:               # from the noise: 2 · ‖σ_r‖ (as uncertainty.SensorNoise.ambiguity_tol)
        ambiguity_tol = 2.0 * float(np.sqrt(np.trace(R)))
        force_floor = max(min_force_N, 5.0 * float(np.sqrt(max(R[0, 0], R[1, 1]))))
    else:
        ambiguity_tol = max(1e-3, 2.0 * float(np.median(rnorm[quiet]))) if quiet.sum() >= 10 else 1e-3
    info.update(min_force_N=force_floor, ambiguity_tol=ambiguity_tol)
    if method == "dynamic":
        if lag_compensation and T > 1:
            dt = observer.regular_period(log.t)
            lag = float(np.mean(observer.lag_s(observer.gains(robot, gain_per_s), dt, discretization)))
            info["lag_compensation_s"] = lag
            q_loc_full = _delayed(log.t, log.q, lag, dt)
        else:
            q_loc_full = log.q
        q_loc = q_loc_full[sel]
        if n_sel:
            res = loc_mod.localize_dynamic(robot, q_loc, r[sel], expected=expected,
                                           row_weights=row_weights, min_force_N=force_floor,
                                           max_condition=max_condition, ambiguity_tol=ambiguity_tol)
        if expected:
            expected_force = np.full((T, len(expected), 2), np.nan)
            quiet = np.flatnonzero(~contact)
            if quiet.size:
                expected_force[quiet] = loc_mod.explain_expected(robot, log.q[quiet], r[quiet],
                                                                 expected, row_weights)[1]
            if n_sel:
                expected_force[sel] = res.expected_force_N
    else:
        thresholds, iso_info = detection.isolation_thresholds(
            robot, log, r, contact, gain_per_s, timing, noise, quiet_window, false_alarm_rate,
            floor=isolation_floor)
        info.update(iso_info, isolation_thresholds=thresholds.tolist())
        if n_sel:
            iso = detection.isolate(r[sel, 3:], thresholds)
            res = loc_mod.localize_paper(robot, log.q[sel], log.dq[sel], tau_meas[sel], iso,
                                         min_force_N=force_floor, max_condition=max_condition)
    if n_sel:
        if method == "dynamic":       # the point at the current posture from the body coordinate α
            qs = log.q[sel]
            jx, jz = loc_mod._joints_link_major(observer.full_robot(robot), qs)
            c0 = np.clip(res.link - 1, 0, robot.n_links - 1)
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
    interval_errors = None
    if method == "dynamic" and R is not None and not expected and n_sel:
        kw = dict(row_weights=row_weights, min_force_N=force_floor, max_condition=max_condition,
                  ambiguity_tol=ambiguity_tol)
        interval_errors = _episode_errors(robot, contact, q_loc_full, r, R, kw)
    return ContactEstimate(interval_errors=interval_errors, t=log.t.copy(), contact=contact, link=link, alpha=alpha, Fx=force[:, 0],
                           Fz=force[:, 1], px=point[:, 0], pz=point[:, 1], rnorm=rnorm,
                           condition=condition, reason=reason, residual=r, method=method,
                           expected_force_N=expected_force, n_skipped=getattr(log, "n_skipped", 0),
                           info=info)
