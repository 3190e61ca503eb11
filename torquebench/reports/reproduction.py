"""The paper's experiments (§IV–V) reproduced: Tables III, IV, V, the posture sweep, Fig. 4, and
the integrator × scene stiffness table. ``build(out_dir)`` writes reports/paper_reproduction.md.

A report of results: each paper scene's scores are its ``paper_scores`` stage
(torquebench.stages.paper, cached), asked of the stage graph by ``results``, the one assembly
that ``torquebench reproduce`` and ``build`` share; this module writes tables and figures.

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

from torquebench.stages.paper import (FILTER_SAMPLES, causal_mean,  # noqa: F401  (the scores)
                                      evaluate_dynamic, evaluate_static, filtered_point)

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
    from userio.errors import InputError
    from estimator.estimate import estimate
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
def results(names=None, *, quick=False, stiffness=True, progress=True, cache=None) -> dict:
    """Each paper scene's ``paper_scores`` from the stage graph (dynamic: simulation → sensor_log
    → scores; static: the holds → scores), cached; then the integrator × scene stiffness table
    (a study of the integrators, not a scene)."""
    from torquebench.cache import Cache
    from torquebench.scenes import load_scene, scene_path
    from torquebench.stages.planner import execute

    cache = Cache() if cache is None else cache
    out = {"dynamic": {}, "static": {}, "timing_s": {}}
    for name in _progress(list(names or ALL_SCENES), "reproduce", progress):
        start = time.perf_counter()
        scene = load_scene(scene_path(name))
        arts, _ = execute(scene, ["paper_scores"], cache)
        out["dynamic" if scene.sim is not None else "static"][scene.name] = arts["paper_scores"]
        out["timing_s"][scene.name] = time.perf_counter() - start
    if stiffness:
        start = time.perf_counter()
        out["stiffness"] = stiffness_table(quick=quick, progress=progress)
        out["timing_s"]["stiffness_table"] = time.perf_counter() - start
    return out


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
         "σ ≈ 0.013 N·m), 1 kHz. Estimator: `estimator.estimate.estimate`, K = 100 1/s, ε_res = 0.06.",
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
    from userio.files import write_text_atomic

    out_dir = Path(out_dir)
    plots = _plots(results, out_dir)
    md = out_dir / "paper_reproduction.md"
    write_text_atomic(md, markdown(results, [p.name for p in plots]))
    return [md, *plots]


def build(out_dir: Path) -> list[Path]:
    """Every paper scene's scores (the stage graph) and the stiffness table; write
    paper_reproduction.md + PNGs."""
    return write(results(progress=True), out_dir)
