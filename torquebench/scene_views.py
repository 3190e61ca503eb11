"""A scene's report as a view of its own stage results: each view takes the artifacts the scene
computed and returns markdown lines and the pictures it drew into the scene's report directory.
Nothing here reads a shipped file or runs an experiment: a view of an artifact the scene did not
compute is not drawn.

A view is one declaration (``View``): its name (the area a scene lists in ``[outputs] reports``),
the artifact it shows, what it is, and its function. Adding a view is adding one entry to VIEWS.
The report stage (torquebench.stages.report.report_areas) reads ``needs``; ``--explain`` lists the views it
draws and why the others are not drawn.

The residual plot keeps units apart: the detection statistic on its own axis (the whitened
√(rᵀR⁻¹r), dimensionless, for the chi-square detector; the paper rule's ‖r‖ of mixed rows, labelled
so), the residual's force rows in N on a second axis and its moment/torque rows in N·m on a third.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from torquebench import formatting as fmt


@dataclass(frozen=True)
class View:
    name: str
    needs: str              # the artifact the view shows
    doc: str
    draw: Callable          # (scene, arts, out_dir) -> (markdown lines, [written paths])


# ---------------------------------------------------------------- pictures
def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _save(fig, path: Path) -> Path:
    from userio.files import atomic_path

    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=110, format="png")
    _pyplot().close(fig)
    return path


def residual_rows(robot) -> list[tuple[str, str]]:
    """(label, unit) of each observer-residual row: the base rows (planar x, z in N and θ in N·m;
    spatial forces then moments), then one joint torque per joint in N·m."""
    n_base = int(getattr(robot, "n_base", 3))
    base = ([("base x", "N"), ("base z", "N"), ("base θ", "N·m")] if n_base == 3 else
            [(f"base f{a}", "N") for a in "xyz"] + [(f"base m{a}", "N·m") for a in "xyz"])
    return base + [(f"joint {j}", "N·m") for j in robot.joint_names]


def statistic_label(est) -> tuple[str, float | None, str]:
    """(axis label, threshold on that axis or None, threshold label) of an estimate's detection
    statistic ``rnorm``: the chi-square detector's √(rᵀR⁻¹r) (dimensionless) against √h, or the
    paper rule's ‖r‖ (N and N·m rows together) against ε."""
    info = est.info or {}
    if str(info.get("detector", "")).startswith("chi-square"):
        h = info.get("chi2_threshold")
        thr = None if h is None or "cusum_threshold" in info else float(np.sqrt(h))
        return "whitened ‖r‖ = √(rᵀR⁻¹r) (dimensionless)", thr, "√χ² threshold"
    return "‖r‖, paper rule (N and N·m rows together)", info.get("threshold"), "ε"


def statistic_groups(methods: dict) -> dict:
    """{axis label: [(name, estimate)]}: estimates whose statistics share a unit share an axis."""
    groups = {}
    for name, e in methods.items():
        groups.setdefault(statistic_label(e)[0], []).append((name, e))
    return groups


def draw_residual(ax, est, robot, methods: dict | None = None) -> None:
    """Draw the residual of ``est`` on the axes ``ax`` (len(statistic_groups(methods)) + 2 of
    them): each detection statistic with its threshold (log scale when positive), then the force
    rows (N), then the moment and torque rows (N·m)."""
    methods = methods or {est.method: est}
    rows = residual_rows(robot)
    r = np.asarray(est.residual, float)
    for a, (label, group) in zip(ax, statistic_groups(methods).items()):
        for name, e in group:
            a.plot(e.t, e.rnorm, lw=0.9, label=f"{name}")
            _, thr, thr_label = statistic_label(e)
            if thr is not None:
                a.axhline(thr, color="r", lw=0.8, ls="--", label=f"{thr_label} ({name}) = {thr:.3g}")
        if all(np.nanmin(e.rnorm) > 0 for _, e in group if np.isfinite(e.rnorm).any()):
            a.set_yscale("log")     # the noise floor, the threshold and a contact on one axis
        a.set_ylabel(label, fontsize=8)
        a.legend(fontsize=7, ncol=2)
    for a, unit, what in ((ax[-2], "N", "force rows"), (ax[-1], "N·m", "moment/torque rows")):
        for k, (name, u) in enumerate(rows[:r.shape[1]]):
            if u == unit:
                a.plot(est.t, r[:, k], lw=0.9, label=f"r {name}")
        a.set_ylabel(f"residual, {what} ({unit})", fontsize=8)
        a.legend(fontsize=7, ncol=3)


def residual_figure(est, robot, truth_on=None, title: str = "", methods: dict | None = None):
    """The observer residual of ``est`` on axes with one unit each (draw_residual): the detection
    statistic of every estimate in ``methods`` ({name: ContactEstimate}, default {est.method: est})
    with its threshold; the force rows (N); the moment and torque rows (N·m). ``truth_on``: (T,)
    bool of the true contact, shaded. Returns the matplotlib Figure (not saved)."""
    plt = _pyplot()
    methods = methods or {est.method: est}
    n_ax = len(statistic_groups(methods)) + 2
    fig, ax = plt.subplots(n_ax, 1, figsize=(8, 2.2 * n_ax + 0.6), sharex=True)
    draw_residual(ax, est, robot, methods)
    if truth_on is not None:
        for a in ax:
            _shade(a, est.t, truth_on)
    ax[0].set_title(title or "momentum-observer residual", fontsize=9)
    ax[-1].set_xlabel("t (s)")
    fig.tight_layout()
    return fig


def _shade(ax, t, on) -> None:
    """Shade the intervals where ``on`` (the true contact)."""
    on = np.asarray(on, bool)
    if not on.any():
        return
    edges = np.flatnonzero(np.diff(np.r_[0, on.astype(int), 0]))
    for a, b in zip(edges[::2], edges[1::2]):
        ax.axvspan(t[a], t[b - 1], color="0.9", zorder=0)


def estimate_figure(ests: dict, truth: dict | None, title: str = ""):
    """The scene's estimate against the truth over time: contact flag, link, α and the force
    components (N), each method one line, the truth in black. ``truth``: per-sample truth rows at
    the estimates' samples (or None for a recorded log). Returns the Figure."""
    plt = _pyplot()
    fig, ax = plt.subplots(4, 1, figsize=(8, 8), sharex=True)
    for i, (name, e) in enumerate(ests.items()):
        ax[0].step(e.t, e.contact.astype(float) + 0.04 * (i + 1), where="post", lw=0.9, label=name)
        ax[1].step(e.t, e.link, where="post", lw=0.9, label=name)
        ax[2].plot(e.t, e.alpha, lw=0.9, label=name)
        ax[3].plot(e.t, e.Fx, lw=0.9, label=f"Fx {name}")
        ax[3].plot(e.t, e.Fz, lw=0.9, label=f"Fz {name}")
    if truth is not None:
        t = next(iter(ests.values())).t
        on = np.asarray(truth["link"]) > 0
        ax[0].step(t, on.astype(float), "k", where="post", lw=0.8, label="truth")
        ax[1].step(t, truth["link"], "k", where="post", lw=0.8, label="truth")
        ax[2].plot(t, np.where(on, truth["alpha"], np.nan), "k", lw=0.8, label="truth")
        ax[3].plot(t, np.where(on, truth["Fx"], np.nan), "k", lw=0.8, label="truth Fx")
        ax[3].plot(t, np.where(on, truth["Fz"], np.nan), "k--", lw=0.8, label="truth Fz")
    for a, lab in zip(ax, ("contact (0/1)", "link", "α (along the link, 0–1)", "F on the robot (N)")):
        a.set_ylabel(lab, fontsize=8)
        a.legend(fontsize=7, ncol=3)
    ax[0].set_title(title, fontsize=9)
    ax[-1].set_xlabel("t (s)")
    fig.tight_layout()
    return fig


def calibration_figure(session, cal):
    """The calibration fit of the scene's session: mass against reading with the fitted mass(reading)
    and its posterior 1σ band, and the residuals mass − fit (g). Returns the Figure."""
    plt = _pyplot()
    unit = cal.reading_unit or "reading units"
    x = np.asarray(session.reading, float)
    m = np.asarray(session.mass_g, float)
    xs = np.linspace(x.min(), x.max(), 200)
    fig, ax = plt.subplots(2, 1, figsize=(7, 6), sharex=True)
    ax[0].plot(x, m, "o", ms=3, label="session")
    fit, sd = cal.mass_g(xs), cal.mass_std_g(xs, include_noise=False)
    ax[0].plot(xs, fit, "k", lw=0.9, label="fit (posterior mean)")
    ax[0].fill_between(xs, fit - sd, fit + sd, color="0.8", label="posterior 1σ")
    ax[0].set_ylabel("mass (g)")
    ax[0].legend(fontsize=8)
    ax[1].plot(x, m - cal.mass_g(x), "o", ms=3)
    ax[1].axhline(0.0, color="k", lw=0.8)
    ax[1].set_ylabel("mass − fit (g)")
    ax[1].set_xlabel(f"reading ({unit})")
    ax[0].set_title("calibration fit of the scene's loading session", fontsize=9)
    fig.tight_layout()
    return fig


def noise_budget_figure(chain):
    """The scene's sensor noise budget: each term's 1σ in N·m per sample and the total."""
    from bridge.budget import noise_budget

    plt = _pyplot()
    b = noise_budget(chain.config, abs(chain.strain_per_Nm))
    terms = {k: v / abs(chain.strain_per_Nm) for k, v in b.terms_strain.items()}
    fig, ax = plt.subplots(figsize=(7, 3))
    names = [*terms, "total"]
    ax.barh(names, [*terms.values(), b.total_Nm], color=["C0"] * len(terms) + ["k"])
    ax.set_xscale("log")
    ax.set_xlabel("torque noise, 1σ per sample (N·m)")
    ax.set_title(f"sensor noise budget at {chain.strain_per_Nm:.3g} strain/N·m", fontsize=9)
    fig.tight_layout()
    return fig


# ---------------------------------------------------------------- the views
def _bridge(scene, arts, out):
    ch = arts["chain"]
    c = ch.config
    rows = [["strain per N·m", f"{ch.strain_per_Nm:.4g}"],
            ["sensitivity", f"{ch.sensitivity_V_per_Nm * 1e3:.4g} mV/N·m"],
            ["ADC counts per N·m", f"{ch.counts_per_Nm:.4g}"],
            ["torque noise σ_τ", f"{ch.noise_std_Nm:.4g} N·m per sample"],
            ["ADC", f"{c.bits} bits, {c.data_rate_Hz:g} S/s, ENOB {c.enob:g}"]]
    path = _save(noise_budget_figure(ch), out / "bridge_noise_budget.png")
    src = scene.chain.sensor_file.name if scene.chain.sensor_file else "the paper's bridge (no [sensor] file)"
    return (["## Sensor chain", "", f"Sensor: {src}.", "", *fmt.markdown_table(["figure", "value"], rows),
             "", f"![noise budget]({path.name})", ""], [path])


def _flexure(scene, arts, out):
    fx = arts["flexure"]
    from flexure.convergence import FIGURES

    rows = [[k, f"{fx[k]:.4g}", f"{fx.get(f'{k}_error_estimate', float('nan')):.2g}"] for k in FIGURES]
    return (["## Flexure (FEM figures)", "", *fmt.markdown_table(["figure", "value", "± error estimate"], rows),
             ""] + [f"- WARNING: {w}" for w in fx.get("warnings", [])] + [""], [])


def _fem(scene, arts, out):
    fx = arts["flexure"]
    from flexure.convergence import FIGURES

    rows = [[k, str(fx.get(f"{k}_error_method", "—"))] for k in FIGURES]
    return ([f"## FEM discretisation ({fx['dofs']} dofs on the finest level)", "",
             *fmt.markdown_table(["figure", "how its error was estimated"], rows), ""], [])


def _calibration(scene, arts, out):
    cal, session = arts["calibration"], arts.get("session")
    L = ["## Calibration", "", f"- {fmt.calibration_text(cal)}", ""]
    if session is None:
        return L + [f"(calibration file {scene.chain.calibration_file.name}: no loading session in "
                    "this scene to plot)", ""], []
    path = _save(calibration_figure(session, cal), out / "calibration_fit.png")
    return L + [f"![calibration fit]({path.name})", ""], [path]


MAX_INTERVAL_ROWS = 10          # detected intervals listed per method


def _scene_truth(arts, est):
    tr = arts.get("truth")
    if tr is None:
        return None
    keep = est["kept"]
    return {k: np.asarray(v)[keep] for k, v in tr["truth"].items()}


def _estimator(scene, arts, out):
    est = arts["estimates"]
    ests = {m: est[m] for m in ("dynamic", "paper") if m in est}
    truth = _scene_truth(arts, est)
    path = _save(estimate_figure(ests, truth, f"scene {scene.name}: estimate"
                                 + (" against the truth" if truth is not None else "")),
                 out / "estimator_vs_truth.png")
    L = ["## Estimate" + (" against the truth" if truth is not None else ""), ""]
    rows, more = [], []
    for m, e in ests.items():
        ivs = e.intervals()
        for iv in ivs[:MAX_INTERVAL_ROWS]:
            rows.append([m, f"{iv['t_start_s']:.3f}–{iv['t_end_s']:.3f}", str(iv.get("link")),
                         f"{iv.get('alpha', float('nan')):.3f}"])
        if len(ivs) > MAX_INTERVAL_ROWS:
            more.append(f"{m}: {len(ivs) - MAX_INTERVAL_ROWS} more intervals not listed")
    if rows:
        L += fmt.markdown_table(["method", "detected interval (s)", "link", "mean α"], rows) + [""]
        L += [f"({'; '.join(more)})", ""] if more else []
    return L + [f"![estimate vs truth]({path.name})", ""], [path]


def _detection(scene, arts, out):
    est = arts["estimates"]
    ests = {m: est[m] for m in ("dynamic", "paper") if m in est}
    first = next(iter(ests.values()))
    truth = _scene_truth(arts, est)
    fig = residual_figure(first, scene.robot, None if truth is None else np.asarray(truth["link"]) > 0,
                          f"scene {scene.name}: momentum-observer residual "
                          f"(K = {scene.estimator.gain_per_s:g} s⁻¹; true contact shaded)", ests)
    path = _save(fig, out / "detection_residual.png")
    L = ["## Detection", ""] + [f"- {m}: {e.info.get('detector', '?')}" for m, e in ests.items()]
    if est.get("noise_source"):
        L.append(f"- sensor noise: {est['noise_source']}")
    return L + ["", f"![residual]({path.name})", ""], [path]


def _reproduction(scene, arts, out):
    ps = arts["paper_scores"]
    if "methods" in ps:
        rows = []
        for m, s in ps["methods"].items():
            cp = s["collision_phase"]
            rows.append([m, f"{100 * s['detected_in_phase']:.1f} %", f"{100 * s['link_correct_in_phase']:.1f} %",
                         f"{cp['mean'][5] * 1e3:.2f} mm" if cp["n"] else "—",
                         f"{cp['mean'][2]:.3f} N" if cp["n"] else "—",
                         f"{100 * s['false_positive_rate']:.2f} %"])
        return (["## Reproduction scores (collision phase)", "",
                 *fmt.markdown_table(["method", "detected", "link right", "mean |Δp|", "mean |ΔF|",
                                      "false positives"], rows), ""], [])
    ok = ~np.asarray(ps["flagged"], bool)
    loc = np.asarray(ps["location_error_m"])[ok]
    return (["## Reproduction scores (static holds)", "",
             f"- {ps['points']} points, {int((~ok).sum())} flagged; location error median "
             f"{fmt.mm(float(np.median(loc)) if loc.size else None)}, max "
             f"{fmt.mm(float(loc.max()) if loc.size else None)}", ""], [])


VIEWS = {v.name: v for v in (
    View("bridge", "chain", "the scene's sensor chain: figures and noise budget", _bridge),
    View("flexure", "flexure", "the scene's flexure figures with their error estimates", _flexure),
    View("fem", "flexure", "how the scene's FEM figures' errors were estimated", _fem),
    View("calibration", "calibration", "the scene's calibration and the fit of its session", _calibration),
    View("estimator", "estimates", "the scene's estimate against its truth over time", _estimator),
    View("detection", "estimates", "the scene's observer residual and detection statistic", _detection),
    View("reproduction", "paper_scores", "the paper reproduction's scores of the scene", _reproduction),
)}
