"""The paper's experiments (§IV–V) reproduced: Tables III, IV, V, the posture sweep, Fig. 4, and
the integrator × scene stiffness table. ``build(out_dir)`` writes reports/paper_reproduction.md.

Definitions used throughout:
- collision phase: the samples with t ∈ [t_on + 5/K, t_off) of the true poke (K the observer gain:
  after 5 time constants the residual has converged to within e⁻⁵ ≈ 0.7 % of the step). The full
  true-contact window (transient included) is reported beside it.
- errors are estimate − truth per sample: Fx, Fz, px, pz signed; |F| = ‖F_est − F_true‖ and
  |p| = ‖p_est − p_true‖. Samples the estimator does not detect, or flags (α = NaN), are left out
  of mean/STD and counted (detected %, flagged %).
- "dynamic + filter": a causal 25-sample (25 ms) moving average of the dynamic estimate's F and α
  (α is a body coordinate; the point is then placed at the current posture).
"""

from __future__ import annotations

import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

PAPER_TABLE_III = {  # mean/STD of Fx, Fz, |F| (N), px, pz, |p| (m)
    "paper_floating_link1": {"mean": [-0.033, 0.051, 0.162, -0.001, 0.000, 0.005],
                             "std": [0.340, 0.379, 0.486, 0.008, 0.002, 0.007]},
    "paper_floating_link2": {"mean": [-0.036, 0.050, 0.121, -0.001, 0.000, 0.002],
                             "std": [0.313, 0.236, 0.378, 0.004, 0.001, 0.003]},
}
PAPER_TABLE_V = {
    "paper_fixed_link1": {"mean": [-0.008, -0.008, 0.112, 0.001, 0.000, 0.003],
                          "std": [0.089, 0.090, 0.058, 0.004, 0.001, 0.002]},
    "paper_fixed_link2": {"mean": [0.002, -0.006, 0.142, 0.000, 0.002, 0.002],
                          "std": [0.108, 0.111, 0.059, 0.002, 0.001, 0.001]},
}
PAPER_TABLE_IV = {(1, 100): (8.89, 0.129), (1, 500): (7.91, 0.174), (2, 50): (4.09, 0.045),
                  (2, 100): (4.87, 0.106)}       # (link, g): RMS location mm, RMS force N (hardware)
PAPER_SWEEP = {"max_location_error_mm": 13.5, "max_force_error_N": 0.15}
DYNAMIC_SCENES = ["paper_floating_link1", "paper_floating_link2", "paper_fixed_link1",
                  "paper_fixed_link2", "moving_leg"]
STATIC_SCENES = ["paper_static_loading", "paper_posture_sweep"]
ALL_SCENES = DYNAMIC_SCENES + STATIC_SCENES
COLS = ["Fx", "Fz", "|F|", "px", "pz", "|p|"]
FILTER_SAMPLES = 25
TARE_S = 0.3          # no-load hold before static loads: the estimator's noise floors come from it



def _save_png(fig, path) -> None:
    """The figure as a PNG written atomically (userio.files: under the command's output plan)."""
    from userio.files import atomic_path

    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=110, format="png")

def _progress(iterable, desc, enabled):
    if not enabled:
        return iterable
    from tqdm import tqdm
    return tqdm(iterable, desc=desc, file=sys.stderr, leave=False)


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
    The detector knows the log's sensor noise (pipeline.scene_noise_model, readings="log";
    ``chain``: the scene's sensor chain for a bridge torque model, else built from the scene)."""
    from estimator.pipeline import estimate
    from torquebench.pipeline import collision_phase_mask, scene_noise_model
    from userio.errors import InputError

    cfg = scene.sim
    K = scene.estimator.gain_per_s
    robot = cfg.robot.with_base(cfg.base == "floating")
    truth, t = res.truth, res.t
    on = truth["link"] > 0
    phase = collision_phase_mask(t, cfg.pokes, K)      # the one definition (torquebench.pipeline)
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


def evaluate_static(scene) -> dict:
    """Static holds (Table IV or the sweep): per-point mean estimate over the window, errors, flags."""
    from estimator.pipeline import estimate
    from estimator.sim.static import static_hold_log
    from estimator.localization import REASONS

    st = scene.static
    pts = st.points
    start = time.perf_counter()
    log, truth, idx = static_hold_log(st.robot, np.array([p.q_rad for p in pts]),
                                      np.array([p.link for p in pts]), np.array([p.alpha for p in pts]),
                                      np.array([p.force_N for p in pts]), st.sensors, st.hold_s,
                                      tare_s=TARE_S)
    sim_s = time.perf_counter() - start
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


def table_iv(res) -> list[dict]:
    rows = []
    labels = np.array(res["labels"])
    for lab in dict.fromkeys(res["labels"]):
        m = labels == lab
        link = int(res["link"][m][0])
        grams = round(float(lab.split(",")[1].strip().split()[0]))
        ls, fs = res["loc_samples"][m], res["force_samples"][m]
        rows.append({"link": link, "load_g": grams,
                     "rms_location_mm": 1e3 * float(np.sqrt(np.nanmean(ls ** 2))),
                     "rms_force_N": float(np.sqrt(np.nanmean(fs ** 2))),
                     "flagged_points": int(res["flagged"][m].sum()),
                     "paper_rms_location_mm": PAPER_TABLE_IV.get((link, grams), (np.nan, np.nan))[0],
                     "paper_rms_force_N": PAPER_TABLE_IV.get((link, grams), (np.nan, np.nan))[1]})
    return rows


def sweep_summary(res) -> dict:
    ok = ~res["flagged"]
    return {"points": int(res["points"]), "flagged": int(res["flagged"].sum()),
            "max_location_error_mm": 1e3 * float(np.nanmax(res["location_error_m"][ok])) if ok.any() else float("nan"),
            "max_force_error_N": float(np.nanmax(res["force_error_N"][ok])) if ok.any() else float("nan"),
            "p99_location_error_mm": 1e3 * float(np.nanpercentile(res["location_error_m"][ok], 99)),
            "median_location_error_mm": 1e3 * float(np.nanmedian(res["location_error_m"][ok])),
            "flagged_reasons": {r: int(sum(1 for rr, f in zip(res["reason"], res["flagged"]) if f and rr == r))
                                for r in sorted(set(res["reason"]))},
            "max_location_error_if_flags_ignored_mm": 1e3 * float(np.nanmax(res["location_error_m"])),
            "paper": PAPER_SWEEP}


# ----------------------------------------------------------------------------- stiffness table
def stiffness_cases(quick: bool = False):
    """(label, SimConfig, integrator settings) for the integrator × scene table (noise-free)."""
    from estimator.robot import paper_leg
    from estimator.sim import Controller, Poke, Sensors, SimConfig

    quiet = Sensors(torque_model="gaussian", torque_noise_Nm=0.0, ft_noise=np.zeros(3))
    dur = 0.2 if quick else 0.5
    poke = (Poke(2, 0.8, 7.0, -np.pi / 3, 0.1 if quick else 0.2, 0.18 if quick else 0.45),)
    ctrl = Controller(q0_rad=np.array([-0.4, -0.8]))
    leg = paper_leg()
    scenes = {
        "floating (Table II mount)": SimConfig(robot=leg, controller=ctrl, pokes=poke, duration_s=dur, sensors=quiet),
        "fixed (stiff mount 1e6)": SimConfig(robot=leg, controller=ctrl, base="fixed", pokes=poke, duration_s=dur, sensors=quiet),
        "floating K_b × 1000": SimConfig(robot=leg, controller=ctrl, pokes=poke, duration_s=dur, sensors=quiet,
                                         mount_stiffness=1000 * leg.base_stiffness, mount_damping=leg.base_damping),
    }
    if quick:
        scenes = {k: v for k, v in list(scenes.items())[:1]}
    integ = [("RK45", {}), ("Radau", {}), ("BDF", {}), ("LSODA", {}), ("RK4", {"fixed_step_s": 5e-5})]
    if quick:
        integ = [("BDF", {}), ("RK4", {"fixed_step_s": 5e-5})]
    cases = []
    for label, cfg in scenes.items():
        for name, kw in integ:
            cases.append((label, "continuous", replace(cfg, integrator=name, **kw)))
        zoh = replace(cfg, controller=replace(ctrl, mode="zoh", rate_Hz=20000.0), integrator="RK4",
                      fixed_step_s=5e-5)
        if not quick:
            cases.append((label, "ZOH 20 kHz", zoh))
        cases.append((label, "ZOH 1 kHz", replace(zoh, controller=replace(ctrl, mode="zoh", rate_Hz=1000.0),
                                                   integrator="BDF")))
    return scenes, cases


def stiffness_table(quick=False, progress=True) -> list[dict]:
    from estimator.errors import InputError
    from estimator.pipeline import estimate
    from estimator.sim import simulate

    scenes, cases = stiffness_cases(quick)
    refs = {label: simulate(replace(cfg, integrator="Radau", rtol=1e-9, atol=1e-11))
            for label, cfg in _progress(scenes.items(), "stiffness refs", progress)}
    rows = []
    for label, control, cfg in _progress(cases, "integrator × scene", progress):
        row = {"scene": label, "control": control, "integrator": cfg.integrator,
               "step": f"h={cfg.fixed_step_s:g} s" if cfg.integrator == "RK4" else f"rtol={cfg.rtol:g}"}
        try:
            res = simulate(cfg)
        except InputError as exc:
            row.update(status="refused", message=str(exc).split(": ", 1)[-1][:400])
            rows.append(row)
            continue
        ref = refs[label]
        robot = cfg.robot.with_base(cfg.base == "floating")
        est = estimate(robot, res.log, method="dynamic")
        p = cfg.pokes[0]
        ph = (res.t >= p.t_on_s + 0.05) & (res.t < p.t_off_s) & est.contact
        dp = np.hypot(est.px - res.truth["px"], est.pz - res.truth["pz"])[ph]
        row.update(status="ok", run_time_s=res.stats["run_time_s"],
                   rhs_evaluations=res.stats["rhs_evaluations"],
                   real_time_factor=res.stats["real_time_factor"],
                   max_q_error_rad=float(np.abs(res.q - ref.q).max()),
                   max_tau_error_Nm=float(np.abs(res.tau_Nm - ref.tau_Nm).max()),
                   mean_location_error_mm=1e3 * float(np.nanmean(dp)) if dp.size else float("nan"))
        rows.append(row)
    return rows


# ----------------------------------------------------------------------------- driver
def run_reproduction(names=None, *, progress=True, quick=False, stiffness=True) -> dict:
    """Run the chosen shipped scenes (default all) and the stiffness table."""
    from estimator.sim import simulate
    from torquebench.scenes import load_scene, scene_path

    names = list(names or ALL_SCENES)
    results = {"dynamic": {}, "static": {}, "timing_s": {}}
    for name in _progress(names, "reproduce", progress):
        start = time.perf_counter()
        scene = load_scene(scene_path(name))
        if scene.sim is not None:
            res = simulate(scene.sim)
            results["dynamic"][scene.name] = evaluate_dynamic(scene, res)
        else:
            results["static"][scene.name] = evaluate_static(scene)
        results["timing_s"][scene.name] = time.perf_counter() - start
    if stiffness:
        start = time.perf_counter()
        results["stiffness"] = stiffness_table(quick=quick, progress=progress)
        results["timing_s"]["stiffness_table"] = time.perf_counter() - start
    return results


def summary(results) -> dict:
    """JSON-able summary (no traces)."""
    out = {"tables": {}, "timing_s": results["timing_s"]}
    for name, r in results["dynamic"].items():
        out["tables"][name] = {
            "collision_phase_s": r["collision_phase_s"],
            "paper_table": (PAPER_TABLE_III.get(name) or PAPER_TABLE_V.get(name)),
            **{m: {"mean": dict(zip(COLS, v["collision_phase"]["mean"])),
                   "std": dict(zip(COLS, v["collision_phase"]["std"])),
                   "detected_in_phase": v["detected_in_phase"],
                   "false_positive_rate": v["false_positive_rate"]}
               for m, v in r["methods"].items()}}
    for name, r in results["static"].items():
        out["tables"][name] = table_iv(r) if r["grid_shape"] == () else sweep_summary(r)
    if "stiffness" in results:
        out["stiffness"] = results["stiffness"]
    return out


# ----------------------------------------------------------------------------- report
def _fmt(x, nd=3):
    return "–" if x is None or not np.isfinite(x) else f"{x:.{nd}f}"


def _plots(results, out_dir: Path) -> list[Path]:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    paths = []
    for name, r in results["dynamic"].items():
        tr = r.get("traces")
        if tr is None:
            continue
        fig, ax = plt.subplots(3, 1, figsize=(8, 8), sharex=True)
        t = tr["t"]
        ax[0].plot(t, tr["F_true"], "k", lw=2, label="true")
        ax[0].plot(t, tr["F_paper"], lw=0.8, label="paper (eqs. 6–9)")
        ax[0].plot(t, tr["F_dynamic"], lw=0.8, label="dynamic")
        ax[0].plot(t, tr["F_dynamic + filter"], lw=1.2, label="dynamic + 25 ms filter")
        ax[0].set_ylabel("|F| (N)")
        ax[0].legend(fontsize=7)
        ax[1].plot(t, tr["alpha_true"], "k", lw=2, label="true")
        ax[1].plot(t, tr["alpha_paper"], ".", ms=1.5, label="paper")
        ax[1].plot(t, tr["alpha_dynamic"], ".", ms=1.5, label="dynamic")
        ax[1].set_ylabel("α")
        ax[1].set_ylim(-0.05, 1.05)
        ax[1].legend(fontsize=7)
        res = tr["residual"]
        labels = ["r_x", "r_z", "r_θ"] + [f"r_q{i}" for i in range(1, res.shape[1] - 2)]
        for k in range(res.shape[1]):
            ax[2].plot(t, res[:, k], lw=0.8, label=labels[k])
        ax[2].plot(t, tr["rnorm"], "k--", lw=0.8, label="‖r‖")
        ax[2].axhline(0.06, color="r", lw=0.6, label="ε_res = 0.06")
        ax[2].set_ylabel("residual (N, N·m)")
        ax[2].set_xlabel("t (s)")
        ax[2].legend(fontsize=6, ncol=4)
        fig.suptitle(f"{name}: true vs estimated |F| and α, observer residual")
        fig.tight_layout()
        p = out_dir / f"reproduction_{name}.png"
        _save_png(fig, p)
        plt.close(fig)
        paths.append(p)
    sw = results["static"].get("paper_posture_sweep")
    if sw is not None and sw["grid_shape"]:
        n1, n2, nl, na = sw["grid_shape"]
        loc = (1e3 * sw["location_error_m"]).reshape(n1, n2, nl * na)
        force = sw["force_error_N"].reshape(n1, n2, nl * na)
        flag = sw["flagged"].reshape(n1, n2, nl * na)
        q1 = np.linspace(0, np.pi, n1)
        q2 = np.linspace(0, np.pi, n2)
        import warnings
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            rms = 1e3 * np.sqrt(np.nanmean(sw["loc_samples"] ** 2, axis=1)).reshape(n1, n2, nl * na)
        fig, ax = plt.subplots(1, 3, figsize=(16, 4.8))
        for a, data, title in ((ax[0], np.where(flag, np.nan, loc), "max location error of the mean estimate (mm)"),
                               (ax[1], np.where(flag, np.nan, rms), "max per-sample RMS location error (mm)"),
                               (ax[2], np.where(flag, np.nan, force), "max force error of the mean estimate (N)")):
            with np.errstate(invalid="ignore"):
                img = np.nanmax(np.where(np.isfinite(data), data, -np.inf), axis=2)
            img = np.where(np.isfinite(img), img, np.nan)
            m = a.imshow(img.T, origin="lower", extent=[-np.pi / 18, np.pi + np.pi / 18] * 2,
                         cmap="viridis", aspect="equal")
            fig.colorbar(m, ax=a)
            nflag = flag.sum(axis=2)
            for i in range(n1):
                for j in range(n2):
                    if nflag[i, j]:
                        a.text(q1[i], q2[j], f"×{nflag[i, j]}", color="red", ha="center",
                               va="center", fontsize=7)
            a.set_xlabel("q1 (rad)")
            a.set_ylabel("q2 (rad)")
            a.set_title(title, fontsize=9)
        fig.suptitle("posture sweep (7 N at −π/3, 8 contacts per posture); red ×n: n contacts flagged")
        fig.tight_layout()
        p = out_dir / "reproduction_sweep_heatmap.png"
        _save_png(fig, p)
        plt.close(fig)
        paths.append(p)
    rows = [r for r in results.get("stiffness", []) if r.get("status") == "ok"]
    if rows:
        fig, ax = plt.subplots(figsize=(7, 4.5))
        for label in dict.fromkeys(r["scene"] for r in rows):
            rr = [r for r in rows if r["scene"] == label]
            for r in rr:
                ax.loglog(r["run_time_s"], max(r["max_tau_error_Nm"], 1e-12), "o")
                ax.annotate(f"{r['integrator']} {r['control'][:3]} / {label.split()[0]}"
                            f"{' K×1000' if '1000' in label else ''}{' stiff' if 'stiff' in label else ''}",
                            (r["run_time_s"], max(r["max_tau_error_Nm"], 1e-12)), fontsize=6)
        ax.set_xlabel("run time (s)")
        ax.set_ylabel("max |τ − τ_ref| (N·m), ref = Radau rtol 1e-9")
        ax.set_title("integrator error against run time")
        fig.tight_layout()
        p = out_dir / "reproduction_integrators.png"
        _save_png(fig, p)
        plt.close(fig)
        paths.append(p)
    return paths


def _targets(results) -> list[str]:
    """The issue's targets, reached or missed, with the numbers."""
    rows = []
    for name, tab in list(PAPER_TABLE_III.items()) + list(PAPER_TABLE_V.items()):
        r = results["dynamic"].get(name)
        if r is None:
            continue
        paper_p = tab["mean"][5]
        for m in ("paper", "dynamic", "dynamic + filter"):
            ours = r["methods"][m]["collision_phase"]["mean"][5]
            goal = paper_p / 2 if m != "paper" and name in PAPER_TABLE_III else paper_p
            what = "≤ ½ paper" if goal < paper_p else "≤ paper"
            rows.append(f"| {name} mean \\|p\\|, {m} | {what}: {1e3 * goal:.1f} mm | {1e3 * ours:.2f} mm | "
                        f"{'reached' if ours <= goal else 'missed'} |")
    sw = results["static"].get("paper_posture_sweep")
    if sw is not None:
        s = sweep_summary(sw)
        rows.append(f"| sweep max location error | < 13.5 mm | {s['max_location_error_mm']:.2f} mm | "
                    f"{'reached' if s['max_location_error_mm'] < 13.5 else 'missed'} |")
        rows.append(f"| sweep max force error | < 0.15 N | {s['max_force_error_N']:.3f} N | "
                    f"{'reached' if s['max_force_error_N'] < 0.15 else 'missed'} |")
    st = results["static"].get("paper_static_loading")
    if st is not None:
        for r in table_iv(st):
            ok = r["rms_location_mm"] <= r["paper_rms_location_mm"]
            rows.append(f"| Table IV link {r['link']}, {r['load_g']} g RMS location (paper: hardware) | "
                        f"≤ {r['paper_rms_location_mm']:.2f} mm | {r['rms_location_mm']:.2f} mm | "
                        f"{'reached' if ok else 'missed'} |")
    if not rows:
        return []
    return ["## Targets", "", "| target | goal | ours | |", "|---|---|---|---|", *rows, "",
            "The `paper` method (eqs. 6–9 as published) solves each sample from the instantaneous",
            "readings (no observer filtering: σ_FT = 0.1 N goes straight into F and, divided by the",
            "lever arm, into α) and is quasi-static (on the floating base the spring-mounted base keeps",
            "moving after the poke, and its inertial forces are read as contact). Where it misses the",
            "paper's numbers, `dynamic` (observer residual on every row) reaches them.",
            "Table IV's 50 g on link 2 (0.49 N) is within 5σ of the FT noise (σ_FT = 0.1 N): its",
            "location RMS misses the hardware figure. False positives (outside true contact, after the",
            "first 0.2 s and 5/K after a release): `paper` keeps the paper's rule ‖r‖ > ε_res = 0.06,",
            "whose are noise excursions at Table II's σ_FT (the debounce option trades them against",
            "latency); `dynamic` detects with the chi-square test at one false alarm per hour on the",
            "residual whitened by the scene's sensor noise (σ_τ of the bridge chain, σ_FT), so what it",
            "still flags there is the residual's decay tail just past 5/K after a release.", ""]


def _headline(lines: list[str]) -> list[str]:
    """The targets reached out of those set (``_targets`` rows), as one sentence."""
    rows = [ln for ln in lines if ln.endswith(("| reached |", "| missed |"))]
    if not rows:
        return []
    missed = [ln.split(" | ")[0].lstrip("| ").replace("\\|", "‖") for ln in rows if ln.endswith("| missed |")]
    return [f"**Headline:** {len(rows) - len(missed)} of {len(rows)} targets against the paper's experiments "
            "reached" + (f"; missed: {', '.join(missed)}" if missed else ""), ""]


def markdown(results, plot_names) -> str:
    L = ["# The paper's experiments, reproduced", "",
         "Generated by `torquebench reproduce` (torquebench/reports/reproduction.py). Simulators:",
         "`estimator.sim` (BDF, rtol 1e-6, continuous PD; checked against the MuJoCo sample log to",
         "1e-8 rad / 3e-6 N·m / 5e-5 N). Sensors: FT noise σ_FT = [0.1 N, 0.1 N, 0.01 N·m] (Table II),",
         "joint torques read through the paper's bridge/ADC chain (`bridge.chain.paper_chain()`,",
         "σ ≈ 0.013 N·m), 1 kHz. Estimator: `estimator.pipeline.estimate`, K = 100 1/s, ε_res = 0.06.",
         "",
         "**Collision phase** = true poke active and t ≥ t_on + 5/K (50 ms after the onset: the",
         "residual has converged to 0.7 %). Errors are estimate − truth per sample; |F| and |p| are the",
         "norms of the vector errors. Undetected or flagged samples are excluded and counted.",
         "\"dynamic + filter\": causal 25 ms moving average of F and α (the point is placed from the",
         "filtered α at the current posture). Static scenes start with a 0.3 s no-load hold (tare).",
         "The paper gives neither posture nor timing: scenes hold q = (−0.4, −0.8) rad and poke on",
         "0.5–1.0 s (see scenes/*.toml).", ""]
    L += _targets(results)
    L[2:2] = _headline(L)
    for title, paper_tab, tag in (("Table III — floating base (simulation)", PAPER_TABLE_III, "III"),
                                  ("Table V — fixed base (simulation, stiff spring mount)", PAPER_TABLE_V, "V")):
        have = [n for n in paper_tab if n in results["dynamic"]]
        if not have:
            continue
        L += [f"## {title}", "", "| scenario | source | stat | Fx (N) | Fz (N) | \\|F\\| (N) | px (m) | pz (m) | \\|p\\| (m) | detected | false pos. |",
              "|---|---|---|---|---|---|---|---|---|---|---|"]
        for n in have:
            r = results["dynamic"][n]
            for stat in ("mean", "std"):
                L.append(f"| {n} | paper | {stat} | " + " | ".join(_fmt(v) for v in paper_tab[n][stat]) + " | | |")
            for m, v in r["methods"].items():
                for stat in ("mean", "std"):
                    s = v["collision_phase"][stat]
                    extra = (f"{100 * v['detected_in_phase']:.0f} % | {100 * v['false_positive_rate']:.1f} %"
                             if stat == "mean" else " | ")
                    L.append(f"| {n} | ours: {m} | {stat} | " + " | ".join(_fmt(x, 4 if i > 2 else 3) for i, x in enumerate(s)) + f" | {extra} |")
        L.append("")
        L.append("Same statistics over the whole true-contact window (onset transient included), mean |p| (m):")
        L.append("")
        for n in have:
            r = results["dynamic"][n]
            L.append(f"- {n}: " + ", ".join(f"{m} {_fmt(v['true_contact_window']['mean'][5], 4)}"
                                              for m, v in r["methods"].items()))
        L.append("")
    if "moving_leg" in results["dynamic"]:
        r = results["dynamic"]["moving_leg"]
        L += ["## Beyond the paper: a poke on a moving leg (`moving_leg`)", "",
              "| method | mean \\|F\\| error (N) | mean \\|p\\| error (mm) | detected | false positives (moving, no contact) |",
              "|---|---|---|---|---|"]
        for m, v in r["methods"].items():
            s = v["collision_phase"]["mean"]
            L.append(f"| {m} | {_fmt(s[2])} | {_fmt(1e3 * s[5], 2)} | {100 * v['detected_in_phase']:.0f} % | "
                     f"{100 * v['false_positive_rate']:.1f} % |")
        L.append("")
    if "paper_static_loading" in results["static"]:
        rows = table_iv(results["static"]["paper_static_loading"])
        L += ["## Table IV — static loading (paper: hardware; ours: fixed-base simulation)", "",
              "Per-sample RMS over the 4 positions (25–100 %) × the last 80 ms of each 150 ms hold",
              "(well-conditioned samples; flagged points are counted, not scored);",
              "posture q = (1.2, −2.4) rad; loads hung as m·g downward.", "",
              "| link | load (g) | paper RMS location (mm) | ours (mm) | paper RMS force (N) | ours (N) | flagged points |",
              "|---|---|---|---|---|---|---|"]
        for r in rows:
            L.append(f"| {r['link']} | {r['load_g']} | {_fmt(r['paper_rms_location_mm'], 2)} | "
                     f"{_fmt(r['rms_location_mm'], 2)} | {_fmt(r['paper_rms_force_N'])} | "
                     f"{_fmt(r['rms_force_N'])} | {r['flagged_points']} |")
        L.append("")
    if "paper_posture_sweep" in results["static"]:
        s = sweep_summary(results["static"]["paper_posture_sweep"])
        L += ["## Posture sweep (10 × 10 grid over [0, π]², 4 contacts per link, 7 N at −π/3)", "",
              "Per point: the mean estimate over the last 80 ms of a 150 ms hold; a point is flagged",
              "when the estimator returns no well-conditioned answer (reason ≠ ok) on most window samples.", "",
              "| quantity | paper | ours |", "|---|---|---|",
              f"| max location error (mm), unflagged points | < 13.5 | {_fmt(s['max_location_error_mm'], 2)} |",
              f"| max force error (N), unflagged points | < 0.15 | {_fmt(s['max_force_error_N'])} |",
              f"| 99th percentile / median location error (mm) | – | {_fmt(s['p99_location_error_mm'], 2)} / {_fmt(s['median_location_error_mm'], 2)} |",
              f"| flagged points | – | {s['flagged']} of {s['points']} ({s['flagged_reasons']}) |",
              f"| max location error if flags were ignored (mm) | – | {_fmt(s['max_location_error_if_flags_ignored_mm'], 1)} |",
              "", "Per-sample RMS location error (noise sensitivity) is where degradation shows: near",
              "straight/folded knees and force directions close to a link's axis the lever arm",
              "|Δ × F| shrinks and single samples scatter; averaging over the window recovers it,",
              "and the points with no well-conditioned answer are flagged (red ×n: n of the 8",
              "contacts at that posture).", "",
              "![sweep](reproduction_sweep_heatmap.png)", ""]
    if "stiffness" in results:
        L += ["## Stiffness and stability: integrator × scene", "",
              "Noise-free 0.5 s scenes (7 N on link 2 at α = 0.8, −π/3, on 0.2–0.45 s). Errors against",
              "Radau at rtol 1e-9; location error of the dynamic estimate over the contact (after 50 ms).",
              "RK4 uses h = 5e-5 s; ZOH 20 kHz is integrated by RK4 at one step per tick.", "",
              "| scene | control | integrator | run time (s) | RHS evals | real-time factor | max \\|Δq\\| (rad) | max \\|Δτ\\| (N·m) | mean \\|p\\| error (mm) |",
              "|---|---|---|---|---|---|---|---|---|"]
        for r in results["stiffness"]:
            if r["status"] != "ok":
                L.append(f"| {r['scene']} | {r['control']} | {r['integrator']} | refused: {r['message']} | | | | | |")
                continue
            L.append(f"| {r['scene']} | {r['control']} | {r['integrator']} ({r['step']}) | {r['run_time_s']:.2f} | "
                     f"{r['rhs_evaluations']} | {r['real_time_factor']:.2f} | {r['max_q_error_rad']:.1e} | "
                     f"{r['max_tau_error_Nm']:.1e} | {_fmt(r['mean_location_error_mm'], 3)} |")
        L += ["", "![integrators](reproduction_integrators.png)", ""]
    for p in plot_names:
        if p.startswith("reproduction_paper") or p.startswith("reproduction_moving"):
            L += [f"![{p}]({p})", ""]
    L += ["## Run times", ""] + [f"- {k}: {v:.1f} s" for k, v in results["timing_s"].items()] + [""]
    return "\n".join(L)


def write(results, out_dir: Path) -> list[Path]:
    from torquebench.io import write_text_atomic

    out_dir = Path(out_dir)
    plots = _plots(results, out_dir)
    md = out_dir / "paper_reproduction.md"
    write_text_atomic(md, markdown(results, [p.name for p in plots]))
    return [md, *plots]


def build(out_dir: Path) -> list[Path]:
    """Run every paper scene and the stiffness table; write paper_reproduction.md + PNGs."""
    return write(run_reproduction(progress=True), out_dir)
