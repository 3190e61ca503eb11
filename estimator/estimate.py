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

import numpy as np

from estimator import cusum_calibration, observer
from estimator import noise as noise_mod
from estimator import timing as timing_mod
from estimator.contact_estimate import ContactEstimate
from estimator.detection import chi2_isf, whitened_sumsq
from userio.errors import InputError
from estimator.log import SensorLog
from estimator.robot import Robot
from estimator.stream import DEFAULT_FALSE_ALARM_RATE, METHODS, STATS_SAMPLES, EstimatorStream


def _expected(robot: Robot, expected_contacts):
    if expected_contacts is None or expected_contacts is False or len(expected_contacts) == 0:
        return ()
    if isinstance(expected_contacts, str):
        if expected_contacts != "foot":
            raise InputError(f"expected contacts: unknown {expected_contacts!r}; use 'foot' or "
                             f"a list of (link, alpha)")
        return ((robot.n_links, 1.0),)
    return tuple((int(k), float(a)) for k, a in expected_contacts)


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
    run = observer.ObserverRun.planar(robot, K, float(period_s), discretization, timing)
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
        stat = whitened_sumsq(np.ascontiguousarray(r.T), np.linalg.inv(np.linalg.cholesky(R)))
    a = float(np.exp(-np.min(K) * float(period_s)))
    n_eff = max(1.0, len(t) * (1 - a) / (1 + a))
    ratio = float(np.median(stat)) / chi2_isf(0.5, n)
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
            cal = cusum_calibration.calibrate_quiet(z, a)
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
    if stream.misfit is not None:
        info["misfit"] = stream.misfit.summary()
    return ContactEstimate(t=cat("t", 0), contact=cat("contact", 0).astype(bool),
                           link=cat("link", 0).astype(int), alpha=cat("alpha", 0), Fx=cat("Fx", 0),
                           Fz=cat("Fz", 0), px=cat("px", 0), pz=cat("pz", 0), rnorm=cat("rnorm", 0),
                           condition=cat("condition", 0), reason=cat("reason", 0).astype(np.int8),
                           residual=cat("residual", (0, n)), method=stream.method,
                           expected_force_N=ef, n_skipped=n_skipped, info=info,
                           interval_list=list(stream.intervals))
