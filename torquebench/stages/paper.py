"""The paper reproduction's scores of one scene (Tables III–V, the posture sweep).

    paper_scores   log (dynamic) or static_log (static) → paper_scores

Definitions:
- collision phase: torquebench.stages.scoring.collision_phase_mask (t ∈ [t_on + ramp + 5/K, t_off)
  of the true poke). The full true-contact window (transient included) is reported beside it.
- errors are estimate − truth per sample: Fx, Fz, px, pz signed; |F| = ‖F_est − F_true‖ and
  |p| = ‖p_est − p_true‖. Samples the estimator does not detect, or flags (α = NaN), are left out
  of mean/STD and counted (detected %, flagged %).
- "dynamic + filter": a causal 25-sample (25 ms) moving average of the dynamic estimate's F and α
  (α is a body coordinate; the point is then placed at the current posture).
"""

from __future__ import annotations

import time
from types import SimpleNamespace

import numpy as np

from torquebench.stages.cachekey import canon
from torquebench.stages.declaration import Stage
from torquebench.stages.noise import scene_noise_model
from torquebench.stages.scoring import collision_phase_mask
from userio.errors import InputError

FILTER_SAMPLES = 25


def causal_mean(x: np.ndarray, n: int) -> np.ndarray:
    """Moving average of the last n finite samples' values (NaNs skipped), per column."""
    x = np.asarray(x, float)
    good = np.isfinite(x)
    v = np.where(good, x, 0.0)
    cs = np.cumsum(np.concatenate([np.zeros((1,) + x.shape[1:]), v]), axis=0)
    cn = np.cumsum(np.concatenate([np.zeros((1,) + x.shape[1:]), good]), axis=0)
    idx = np.arange(1, len(x) + 1)
    lo = np.maximum(idx - n, 0)
    s, c = cs[idx] - cs[lo], cn[idx] - cn[lo]
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(c > 0, s / np.maximum(c, 1), np.nan)


def filtered_point(robot, q, est, n):
    """p from the causal n-sample mean of α (a body coordinate) at the CURRENT posture, per link."""
    from estimator import dynamics as dyn

    full = robot.with_base(True)
    a = np.where(est.contact, est.alpha, np.nan)
    af = causal_mean(a[:, None], n)[:, 0]
    p = np.full((len(a), 2), np.nan)
    for c in range(1, robot.n_links + 1):
        rows = est.contact & (est.link == c) & np.isfinite(af)
        if rows.any():
            p[rows] = dyn.contact_point(full, q[rows], c, af[rows])
    return p


def _errors(est_F, est_p, truth):
    """Per-sample signed errors (T, 6): Fx, Fz, |ΔF|, px, pz, |Δp|."""
    dF = est_F - np.column_stack([truth["Fx"], truth["Fz"]])
    dp = est_p - np.column_stack([truth["px"], truth["pz"]])
    return np.column_stack([dF, np.hypot(*dF.T), dp, np.hypot(*dp.T)])


def _stats(err, mask):
    e = err[mask]
    e = e[np.all(np.isfinite(e), axis=1)]
    if len(e) == 0:
        return {"mean": [float("nan")] * 6, "std": [float("nan")] * 6, "n": 0}
    return {"mean": e.mean(0).tolist(), "std": e.std(0).tolist(), "n": int(len(e))}


def evaluate_dynamic(scene, res, *, with_traces=True, chain=None) -> dict:
    """Estimate a simulated dynamic scene with both methods (+ filtered dynamic) and score them.
    The detector knows the log's sensor noise (torquebench.stages.noise, readings="log";
    ``chain``: the scene's sensor chain for a bridge torque model, else built from the scene)."""
    from estimator.estimate import estimate

    cfg = scene.sim
    K = scene.estimator.gain_per_s
    robot = cfg.robot.with_base(cfg.base == "floating")
    truth, t = res.truth, res.t
    on = truth["link"] > 0
    phase = collision_phase_mask(t, cfg.pokes, K)      # the one definition (stages.scoring)
    quiet = ~on & (t > 0.2)
    for p in cfg.pokes:   # the observer's decay after a poke ends is not a false positive
        quiet &= ~((t >= p.t_off_s) & (t < p.t_off_s + p.ramp_s + 5.0 / K))
    out = {"scene": scene.name, "collision_phase_s": [float(t[phase][0]) if phase.any() else None,
                                                      float(t[phase][-1]) if phase.any() else None],
           "methods": {}, "sim": res.stats}
    traces = {"t": t, "F_true": np.hypot(truth["Fx"], truth["Fz"]), "alpha_true": truth["alpha"],
              "link_true": truth["link"]}
    try:
        noise = scene_noise_model(scene, chain, readings="log")
    except InputError:
        if scene.estimator.threshold is None:
            raise
        noise = None                      # the scene's own ε: the paper rule, as before
    for method in ("paper", "dynamic"):
        start = time.perf_counter()
        est = estimate(robot, res.log, method=method, gain_per_s=K, threshold=scene.estimator.threshold,
                       noise=noise, false_alarm_rate=scene.estimator.false_alarm_rate)
        run_s = time.perf_counter() - start
        F = np.column_stack([est.Fx, est.Fz])
        p = np.column_stack([est.px, est.pz])
        variants = {method: (F, p)}
        if method == "dynamic":
            Ff = np.where(est.contact[:, None], causal_mean(np.where(est.contact[:, None], F, np.nan),
                                                            FILTER_SAMPLES), np.nan)
            pf = filtered_point(cfg.robot, res.log.q, est, FILTER_SAMPLES)
            variants["dynamic + filter"] = (Ff, pf)
            traces["residual"] = est.residual
            traces["rnorm"] = est.rnorm
        for name, (FF, pp) in variants.items():
            err = _errors(FF, pp, truth)
            out["methods"][name] = {
                "collision_phase": _stats(err, phase & est.contact),
                "true_contact_window": _stats(err, on & est.contact),
                "detected_in_phase": float(est.contact[phase].mean()) if phase.any() else float("nan"),
                "flagged_in_phase": float(np.mean(~np.isfinite(pp[phase, 0]))) if phase.any() else float("nan"),
                "link_correct_in_phase": float(np.mean(est.link[phase] == truth["link"][phase]))
                if phase.any() else float("nan"),
                "false_positive_rate": float(est.contact[quiet].mean()) if quiet.any() else 0.0,
                "estimate_time_s": run_s}
            traces[f"F_{name}"] = np.hypot(*FF.T)
            a = est.alpha.copy() if name == method else np.full(len(t), np.nan)
            traces[f"alpha_{name}"] = a
    if with_traces:
        out["traces"] = traces
    return out


def evaluate_static(scene, holds=None) -> dict:
    """Static holds (Table IV or the sweep): per-point mean estimate over the window, errors, flags.
    ``holds``: the scene's static_holds result (computed here when not given)."""
    from estimator.localization import REASONS
    from estimator.estimate import estimate

    from torquebench.stages.simulation import run_static_holds

    st = scene.static
    pts = st.points
    holds = run_static_holds(scene, {}) if holds is None else holds
    log, truth, idx = holds["log"], holds["truth"], holds["index"]
    sim_s = holds["stats"]["run_time_s"]
    start = time.perf_counter()
    est = estimate(st.robot, log, method=scene.estimator.method, gain_per_s=scene.estimator.gain_per_s,
                   threshold=scene.estimator.threshold)
    est_s = time.perf_counter() - start
    per = int(round(st.hold_s * st.sensors.sample_rate_Hz))
    win = int(round(st.window_s * st.sensors.sample_rate_Hz))
    P = len(pts)
    sel = (np.arange(per) >= per - win)
    loaded = idx >= 0
    W = lambda x: np.asarray(x, float)[loaded].reshape(P, per)[:, sel]   # noqa: E731
    F_true = np.array([p.force_N for p in pts])
    pt = np.column_stack([W(truth["px"])[:, 0], W(truth["pz"])[:, 0]])
    ok = W(est.contact) > 0.5
    ok &= W(est.reason) == REASONS.index("ok")
    flagged = ok.mean(1) < 0.5
    def wmean(x):
        x = np.where(ok, W(x), np.nan)
        with np.errstate(invalid="ignore"):
            return np.nanmean(np.where(np.isfinite(x), x, np.nan), axis=1) if True else None
    import warnings
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        Fm = np.column_stack([wmean(est.Fx), wmean(est.Fz)])
        pm = np.column_stack([wmean(est.px), wmean(est.pz)])
    loc_err = np.hypot(*(pm - pt).T)
    force_err = np.hypot(*(Fm - F_true).T)
    # per-sample errors (for RMS): all window samples with a well-conditioned answer
    ps = np.stack([W(est.px), W(est.pz)], -1) - pt[:, None, :]
    fs = np.stack([W(est.Fx), W(est.Fz)], -1) - F_true[:, None, :]
    loc_s = np.where(ok, np.linalg.norm(ps, axis=-1), np.nan)
    force_s = np.where(ok, np.linalg.norm(fs, axis=-1), np.nan)
    # condition: 1/|sin∠(F, link)|, median over the window (NaN where undetermined)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        cond = np.nanmedian(W(est.condition), axis=1)
        reasons = [REASONS[int(np.bincount(r).argmax())] for r in W(est.reason).astype(int)]
    return {"scene": scene.name, "points": P, "labels": [p.label for p in pts],
            "q": np.array([p.q_rad for p in pts]), "link": np.array([p.link for p in pts]),
            "alpha": np.array([p.alpha for p in pts]), "location_error_m": loc_err,
            "force_error_N": force_err, "flagged": flagged, "reason": reasons, "condition": cond,
            "loc_samples": loc_s, "force_samples": force_s, "grid_shape": st.grid_shape,
            "simulate_s": sim_s, "estimate_s": est_s, "samples": len(log.t)}


def run_paper_scores(scene, inp, seed=None):
    """The scores of a dynamic scene's simulated log through both methods, or of a static scene's
    holds."""
    if scene.sim is None:
        return evaluate_static(scene, inp.get("static_log"))
    lg = inp["log"]
    res = SimpleNamespace(t=lg["log"].t, truth=lg["truth"], log=lg["log"], stats=lg["stats"])
    return evaluate_dynamic(scene, res, chain=inp.get("chain"))


def _uses(scene, art):
    if art == "log":
        return scene.sim is not None
    if art == "static_log":
        return scene.sim is None
    return scene.sim is not None and scene.sim.sensors.torque_model == "bridge"   # σ_τ of a bridge log


STAGES = (
    Stage("paper_scores", "paper_scores", "the paper reproduction's scores of the scene", run_paper_scores,
          needs=("log?", "static_log?", "chain?"), reads=("name", "estimator", "poke", "static"),
          params=lambda scene, seed: {
              "name": scene.name, "est": canon(scene.estimator),
              "scene": canon(scene.sim.pokes) if scene.sim is not None else canon(scene.static)},
          feasible=lambda scene: None if scene.sim is not None or scene.static is not None else
          "no simulated scene to score",
          uses=_uses),
)
