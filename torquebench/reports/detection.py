"""reports/detection.md: contact detection against sensor noise.

Simulated logs of the paper leg (inverse dynamics on a 5 kHz grid, read out at 1 kHz as
instantaneous states and interval-mean forces, the issue's noise: FT σ 0.1 N, 0.1 N, 0.01 N·m,
joint torque σ 0.005 N·m, declared ``mean``). Scenes: static (joints held, base still) and moving
(base shaking at 10 Hz, joints swinging). Measured when the report is built:

* empirical false-alarm rate of the chi-square detector and of the CUSUM (estimator.sequential)
  on 10⁶ contact-free samples per scene;
* ROC: P(detect within 20 ms) against false alarms per hour, pokes 0.02–10 N, chi-square detector,
  CUSUM and the paper rule ‖r‖ > ε (whose false-alarm axis is measured on the contact-free log);
* detection delay against magnitude at one false alarm per hour, chi-square vs CUSUM;
* the cost of a wrong timing declaration.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from userio.files import atomic_path, write_text_atomic
from userio.outputs import make_dir

SUB, RATE = 5, 1000.0
SIGMA = np.array([0.1, 0.1, 0.01, 0.005, 0.005])
MAGNITUDES_N = (0.02, 0.03, 0.05, 0.1, 0.2, 0.5, 1.0, 2.0, 3.0, 5.0, 10.0)
ROC_MAGNITUDES_N = (0.02, 0.05, 0.1, 0.2)
WINDOW_S = 0.020


def _motion(robot, t, scene):
    from estimator.synthetic import sinusoidal_motion

    if scene == "static":
        q = np.tile([0.0, 0.0, 0.0, 0.9, -1.6], (len(t), 1))
        return q, np.zeros_like(q), np.zeros_like(q)
    return sinusoidal_motion(robot, t, q0=(0.9, -1.6), frequency_Hz=10.0, amplitude_rad=(0.05, 0.05),
                             base_amplitude=(0.001, 0.002, 0.01))


def simulated_log(robot, duration_s, scene, force_N=None, alpha=0.5, link=2, seed=0,
                  readout="mean"):
    """SensorLog (declared ``readout``) with per-sample poke force ``force_N`` (T_log, 2) or None."""
    from estimator import timing
    from estimator.log import SensorLog
    from estimator.synthetic import inverse_dynamics_log

    T = int(round(duration_s * RATE))
    tf = np.arange(T * SUB + 1) / (RATE * SUB)
    q, dq, ddq = _motion(robot, tf, scene)
    if force_N is None:
        F = np.zeros((len(tf), 2))
    else:                                   # held over each log interval (t_{k−1}, t_k]
        F = np.repeat(np.vstack([force_N[:1], force_N]), SUB, axis=0)[SUB - 1:SUB - 1 + len(tf)]
    fine, _ = inverse_dynamics_log(robot, tf, q, dq, ddq, link, alpha, F)
    f = fine.tau_meas
    idx = np.arange(0, len(tf), SUB)[:T]
    if readout == "mean":
        c = np.concatenate([np.zeros((1, 5)), np.cumsum(0.5 * (f[1:] + f[:-1]), axis=0)])
        out = f[idx].copy()
        out[1:] = (c[idx[1:]] - c[idx[:-1]]) / SUB
    else:
        out = f[idx]
    out = out + np.random.default_rng(seed).standard_normal(out.shape) * SIGMA
    log = SensorLog(t=tf[idx], q=q[idx], dq=dq[idx], tau_Nm=out[:, 3:], wrench=out[:, :3])
    log.timing = timing.uniform(readout, 2)
    return log


TAIL_WINDOW = 300               # samples after a poke's end searched for its last flag


def _pokes(T, magnitude, seed, period=500, on=100):
    """Per-sample force (T, 2): pokes of ``on`` samples every ``period``, random directions."""
    rng = np.random.default_rng(seed)
    starts = np.arange(period // 2, T - on, period)
    ang = rng.uniform(0, 2 * np.pi, len(starts))
    F = np.zeros((T, 2))
    for s, a in zip(starts, ang):
        F[s:s + on] = magnitude * np.array([np.cos(a), np.sin(a)])
    return F, starts


def _stats(robot, log):
    """(chi-square statistic s_k, ‖r‖, chi2 dof) on a log with the default detector settings."""
    from estimator.estimate import estimate

    est = estimate(robot, log)
    paper = np.linalg.norm(est.residual, axis=1)
    return est.rnorm ** 2, paper, est.info["chi2_dof"]


def _calibration(robot, log):
    """The CUSUM calibration the pipeline uses for these logs (paper leg noise, declared timing)."""
    from estimator import cusum_calibration, observer
    from estimator.noise import paper_leg_noise

    return cusum_calibration.model_calibration(robot, log.q[0], log.dq[0], paper_leg_noise(), 100.0,
                                               observer.regular_period(log.t), log.timing)


def _onsets(flag) -> int:
    f = np.asarray(flag, np.int8)
    return int(np.count_nonzero(np.diff(f) == 1) + f[0])


def _first(flag_win) -> np.ndarray:
    """Samples from the poke onset to the first flag (1-based), NaN when none in the window."""
    first = np.argmax(flag_win, axis=1).astype(float) + 1
    first[~flag_win.any(axis=1)] = np.nan
    return first


def _tail(flag_win) -> np.ndarray:
    """Samples from a poke's end to the end of its last flag in the window (0 when none)."""
    f = np.asarray(flag_win, bool)
    last = f.shape[1] - np.argmax(f[:, ::-1], axis=1)
    return np.where(f.any(axis=1), last, 0).astype(float)


def _save(fig, path: Path) -> Path:
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=110, format="png")
    return path


def build(out_dir: Path, quick: bool = False) -> list[Path]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from scipy.stats import chi2

    from estimator.estimate import estimate
    from estimator.robot import paper_leg
    from estimator.sequential import cusum

    robot = paper_leg()
    out_dir = Path(out_dir)
    make_dir(out_dir, "output directory")
    start = time.perf_counter()
    n_quiet_s = 100.0 if quick else 1000.0
    dt = 1.0 / RATE
    a_1h = dt / 3600
    lines = ["# Contact detection against sensor noise", "",
             "Paper leg, simulated (inverse dynamics on a 5 kHz grid, 1 kHz log, forces read as "
             "interval means and declared `mean`), noise FT σ = 0.1 N, 0.1 N, 0.01 N·m, joint torque "
             "σ = 0.005 N·m; observer K = 100 /s. Detectors on the residual whitened by its covariance "
             "predicted from the noise model (`estimator/noise.py`), s_k = r_kᵀR⁻¹r_k: **chi-square** "
             "(flag s_k > h, P(χ²_n > h) = α per sample; the default) and **CUSUM** "
             "(`estimator/sequential.py`: g_k = min(h, max(0, g_{k−1} + s_k − n − δ)), δ = n, alarm "
             "from g = h until g = 0; h from the target mean time between alarm onsets, with the alarm "
             "rate as a function of h measured on a seeded Monte Carlo of the residual's own model: "
             "a free run where alarms are frequent, multilevel splitting where they are rare); "
             "paper rule: ‖r‖ > ε. Built by `torquebench report --only detection`.", ""]
    paths = []
    # --------------------------------------------------------------- false alarms, contact free
    lines += ["## False alarms on contact-free logs", "",
              f"{int(n_quiet_s * RATE):,} samples per scene (100 s "
              "segments, the first 0.2 s of each dropped). Expected count = target × samples.", "",
              "### Chi-square detector (target = flagged fraction per sample)", "",
              "Sampling σ of the flagged fraction: √(α/n_eff), n_eff = samples·(1 − a)/(1 + a) with "
              "a = exp(−KΔt) (the residual's correlation time); the deviation is in those σ. Flagged "
              "samples come in runs (the residual is correlated), so alarm onsets are fewer than "
              "flagged samples: the onsets column is what a user counts as false alarms.", "",
              "| scene | target per sample | expected flagged | flagged | flagged fraction | deviation σ | onsets |",
              "|---|---|---|---|---|---|---|"]
    quiet = {}
    per_hour = {}                 # scene → (flagged, expected, samples) at one false alarm per hour
    cal = {}
    cal_seconds = 0.0
    for scene in ("static", "moving"):
        parts, wrong = [], []
        for seg in range(int(np.ceil(n_quiet_s / 100.0))):      # 100 s segments: bounded memory
            log = simulated_log(robot, 100.0, scene, seed=(11 if scene == "static" else 1011) + seg)
            if seg == 0:
                t_cal = time.perf_counter()
                cal[scene] = _calibration(robot, log)
                cal_seconds = max(cal_seconds, time.perf_counter() - t_cal)
            s, paper, n = _stats(robot, log)
            parts.append((s[200:], paper[200:]))
            if seg == 0:
                wrong.append(estimate(robot, log, timing="instant").contact[200:].mean())
        s = np.concatenate([p[0] for p in parts])
        paper = np.concatenate([p[1] for p in parts])
        quiet[scene] = (s, paper, n)
        quiet[scene + "_wrong"] = wrong[0]
        ac = np.exp(-100.0 * dt)
        n_eff = len(s) * (1 - ac) / (1 + ac)
        for a in (1e-2, 1e-3, 1e-4, a_1h):
            flag = s > chi2.isf(a, n)
            k = int(flag.sum())
            dev = (k / len(s) - a) / np.sqrt(a / n_eff)
            if a == a_1h:
                per_hour[scene] = (k, a * len(s), len(s))
            lines.append(f"| {scene} | {a:.3g}{' (1/h)' if a < 1e-6 else ''} | {a * len(s):.3g} | {k} | "
                         f"{k / len(s):.3g} | {dev:+.1f} | {_onsets(flag)} |")
        lines.append(f"| {scene} | paper ε = 0.06 | – | {int((paper > 0.06).sum())} | "
                     f"{(paper > 0.06).mean():.3g} | – | {_onsets(paper > 0.06)} |")
    lines += ["", "### CUSUM (target = mean time between alarm onsets)", "",
              "Same statistic and logs. Sampling σ of the count: √expected (alarm onsets are separated "
              "by regeneration points g = 0, so the count is close to Poisson) combined with the "
              "calibration's own 1σ error of the rate at h; deviation in that σ. "
              "The 1/h row cannot be checked on 10⁶ samples (0.28 expected): its threshold comes from "
              "the same calibration's splitting levels (checked at 10⁻⁵ per sample below).", "",
              "| scene | target | threshold h (χ² units) | calibration 1σ | expected alarms | alarms | deviation σ | flagged fraction |",
              "|---|---|---|---|---|---|---|---|"]
    for scene in ("static", "moving"):
        s, _, n = quiet[scene]
        c = cal[scene]
        for rate_s, label in ((1.0, "1/s"), (0.1, "0.1/s"), (0.01, "0.01/s"), (1 / 3600, "1/h")):
            h = c.threshold(rate_s * dt)
            flag, _ = cusum(s, n, h, c.drift)
            k = _onsets(flag)
            exp = rate_s * dt * len(s)
            ce = c.rate_rel_error(h)
            sig = exp * np.hypot(1 / np.sqrt(exp), ce)
            lines.append(f"| {scene} | {label} | {h:.1f} | {100 * ce:.1f} % | {exp:.3g} | {k} | "
                         f"{(k - exp) / sig:+.1f} | {flag.mean():.3g} |")
    lines.append("")
    # the threshold formula alone, on a long synthetic run of the same residual process
    from estimator import noise as noise_mod
    from estimator import cusum_calibration as seq

    n_syn = 1_000_000 if quick else 6_000_000
    q0 = np.array([0.0, 0.0, 0.0, 0.9, -1.6])
    tim = [("mean", 0.0)] * 5
    fa, fb, B0, B1 = noise_mod.filter_terms(robot, q0, 0 * q0, noise_mod.paper_leg_noise(), 100.0, dt, tim)
    R0 = noise_mod.residual_covariance(robot, q0, 0 * q0, noise_mod.paper_leg_noise(), 100.0, dt, tim)[0]
    s_syn = seq.synthetic_statistic(fa, fb, B0[0], B1[0], R0, n_syn, seed=2024)
    c0 = cal["static"]
    lines += [f"The threshold alone, on {n_syn:,} samples of a synthetic residual of the same "
              f"model (seed 2024; the calibration uses seed {seq.CAL_SEED}). σ: Poisson σ of the "
              "count and the calibration's own 1σ, combined; deviation in that σ:", "",
              "| target per sample | threshold h | expected alarms | alarms | measured / target | "
              "Poisson σ | calibration σ | deviation σ |",
              "|---|---|---|---|---|---|---|---|"]
    worst = 0.0
    for a in (1e-2, 1e-3, 1e-4, 1e-5):
        h = c0.threshold(a)
        flag, _ = cusum(s_syn, 5, h, c0.drift)
        k, exp = _onsets(flag), a * n_syn
        ce = c0.rate_rel_error(h)
        dev = (k - exp) / (exp * np.hypot(1 / np.sqrt(exp), ce))
        worst = max(worst, abs(dev))
        lines.append(f"| {a:g} | {h:.1f} | {exp:.3g} | {k} | {k / exp:.3f} | {100 / np.sqrt(exp):.1f} % | "
                     f"{100 * ce:.1f} % | {dev:+.1f} |")
    lines += ["", f"Largest deviation: {worst:.1f} σ. The splitting measures the whole curve rate(h); "
              f"θ* = {c0.theta:.4g} (the whitened residual's large-deviation exponent) is used only "
              f"below {seq.RATE_FLOOR:g} per sample, where it bounds the slope from below "
              "(conservative). It sits at the spectral singularity 1/(2 max λ), where log ARL(h) "
              "approaches its asymptotic slope only slowly; that is why the previous threshold "
              "formula (Siegmund's form with a prefactor fitted at θ*h = 1–3) missed by up to 24 %.",
              "", f"Calibration (static): {c0.method}; δ = {c0.drift:g}; it took "
              f"{cal_seconds:.1f} s in this run (loaded machine; numba's compilation included when its "
              "cache is cold).", ""]
    lines += ["", "## Cost of a wrong timing declaration", "",
              "Interval-mean readings declared `instant` (half a sample of skew), chi-square detector at 1/h:", ""]
    for scene in ("static", "moving"):
        lines.append(f"- {scene}: {100 * quiet[scene + '_wrong']:.3g} % of contact-free samples flagged "
                     f"(correctly declared: "
                     f"{100 * (quiet[scene][0] > chi2.isf(a_1h, quiet[scene][2])).mean():.3g} %)")
    # --------------------------------------------------------------- ROC and delay
    n_pokes = 20 if quick else 60
    T = 500 * n_pokes + 250
    w = int(WINDOW_S * RATE)
    on = 100
    roc, delays, tails = {}, {}, {}
    fa_h = np.logspace(-1, 4, 60)
    fa_cusum = np.logspace(-1, 4, 16)
    for scene in ("static", "moving"):
        c = cal[scene]
        h_1h = c.threshold(a_1h)
        h_grid = np.array([c.threshold(f * dt / 3600) for f in fa_cusum])
        for mag in MAGNITUDES_N:
            F, starts = _pokes(T, mag, seed=int(mag * 10))
            log = simulated_log(robot, T / RATE, scene, force_N=F, seed=int(mag * 100) + 1)
            s, paper, n = _stats(robot, log)
            win = starts[:, None] + np.arange(1, w + 1)[None]
            held = starts[:, None] + np.arange(1, on + 1)[None]
            smax, pmax = s[win].max(axis=1), paper[win].max(axis=1)
            pd_cusum = None
            if mag in ROC_MAGNITUDES_N:
                pd_cusum = np.array([cusum(s, n, hh, c.drift)[0][win].any(axis=1).mean() for hh in h_grid])
            roc[(scene, mag)] = (smax, pmax, pd_cusum)
            h = chi2.isf(a_1h, n)
            flag_c, _ = cusum(s, n, h_1h, c.drift)
            delays[(scene, mag)] = (_first(s[held] > h) * dt, _first(flag_c[held]) * dt)
            after = (starts + on)[:, None] + np.arange(TAIL_WINDOW)[None]
            tails[(scene, mag)] = (_tail(s[after] > h) * dt, _tail(flag_c[after]) * dt)
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2), sharey=True)
    for ax, scene in zip(axes, ("static", "moving")):
        s_q, p_q, n = quiet[scene]
        p_sorted = np.sort(p_q)[::-1]
        for i, mag in enumerate(ROC_MAGNITUDES_N):
            smax, pmax, pd_cusum = roc[(scene, mag)]
            hs = chi2.isf(np.clip(fa_h * dt / 3600, 1e-300, 1), n)
            ax.semilogx(fa_h, (smax[:, None] > hs[None]).mean(axis=0), color=f"C{i}", label=f"{mag:g} N")
            ax.semilogx(fa_cusum, pd_cusum, color=f"C{i}", ls=":", marker=".")
            # paper rule: thresholds from the contact-free ‖r‖ (FA measurable down to 1/log length)
            k = np.clip((fa_h * dt / 3600 * len(p_sorted)).astype(int), 0, len(p_sorted) - 1)
            ok = fa_h * dt / 3600 * len(p_sorted) >= 1
            eps = p_sorted[k]
            pd_paper = (pmax[:, None] > eps[None]).mean(axis=0)
            ax.semilogx(fa_h[ok], pd_paper[ok], color=f"C{i}", ls="--")
        ax.axvline(1.0, color="k", lw=0.7)
        ax.set_ylim(-0.02, 1.02)
        ax.set_title(f"{scene}: P(detect within 20 ms)")
        ax.set_xlabel("false alarms per hour (target of the threshold)")
        ax.grid(True, which="both", alpha=0.3)
    axes[0].set_ylabel("detection probability")
    handles, labels = axes[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncol=len(labels), fontsize=8,
               title="poke (solid: chi-square, dotted: CUSUM, dashed: ‖r‖ > ε)")
    fig.subplots_adjust(bottom=0.3)
    paths.append(_save(fig, out_dir / "detection_roc.png"))
    plt.close(fig)
    lines += ["", "## ROC and delay", "", "![ROC](detection_roc.png)", "",
              f"{n_pokes} pokes per magnitude (random direction, link 2, α = 0.5, held 100 ms; the "
              "grid goes below the issue's 0.5 N because every poke ≥ 0.5 N is detected at once). "
              "The chi-square and CUSUM curves use the false-alarm rate their thresholds are set for "
              "(validated above; for the chi-square detector that is the flagged fraction, an upper "
              "bound on its alarm onsets, which favours it in this comparison); the paper rule's axis "
              "is measured on the contact-free log. At one false alarm per hour (delay from the "
              "poke's onset; 'held' = within the 100 ms the poke lasts):", "",
              "| scene | poke N | chi-square P(≤ 20 ms) | P(held) | median delay ms (detected) | CUSUM P(≤ 20 ms) | "
              "P(held) | median delay ms (detected) | paper ε = 0.06: P(≤ 20 ms) |",
              "|---|---|---|---|---|---|---|---|---|"]
    smallest = {}
    fig, ax = plt.subplots(figsize=(6.5, 4.2))
    for scene, ls in (("static", "-"), ("moving", "--")):
        med = {0: [], 1: []}
        for mag in MAGNITUDES_N:
            row = [scene, f"{mag:g}"]
            for j in (0, 1):
                d = delays[(scene, mag)][j]
                p20 = float((d <= WINDOW_S + 1e-12).mean())
                md = float(np.nanmedian(d)) * 1e3 if np.isfinite(d).any() else float("nan")
                med[j].append(md)
                row += [f"{p20:.2f}", f"{float(np.isfinite(d).mean()):.2f}", f"{md:.1f}"]
                if j == 0 and p20 >= 0.95 and scene not in smallest:
                    smallest[scene] = mag
            row.append(f"{float((roc[(scene, mag)][1] > 0.06).mean()):.2f}")
            lines.append("| " + " | ".join(row) + " |")
        ax.plot(MAGNITUDES_N, med[0], ls, marker="o", color="C0", label=f"chi-square, {scene}")
        ax.plot(MAGNITUDES_N, med[1], ls, marker="s", color="C3", label=f"CUSUM, {scene}")
    ax.set_xscale("log")
    ax.set_xlabel("poke magnitude N")
    ax.set_ylabel("median detection delay ms (1 false alarm/h)")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    paths.append(_save(fig, out_dir / "detection_delay.png"))
    plt.close(fig)
    lines += ["", "![delay](detection_delay.png)", ""]
    for scene in ("static", "moving"):
        lines.append(f"- Smallest poke of the grid detected within 20 ms in ≥ 95 % of trials at one "
                     f"false alarm per hour (chi-square), {scene}: "
                     f"{smallest.get(scene, float('nan')):g} N (grid {', '.join(map(str, MAGNITUDES_N))} N).")
    h_s = cal["static"].threshold(a_1h)
    big = [m for m in MAGNITUDES_N if m >= 0.5]
    tail_c = {sc: float(np.median(np.concatenate([tails[(sc, m)][1] for m in big]))) * 1e3
              for sc in ("static", "moving")}
    tail_x = {sc: float(np.median(np.concatenate([tails[(sc, m)][0] for m in big]))) * 1e3
              for sc in ("static", "moving")}
    lines += ["", "### Which detector by default", "",
              f"At one false alarm per hour the CUSUM threshold is h = {h_s:.0f} χ² units with drift δ = "
              f"{cal['static'].drift:g}: it accumulates evidence, so it finds more of the smallest held "
              "pokes (the 'P(held)' columns at 0.02–0.03 N), but for pokes ≥ 0.05 N its median delay is "
              "longer than the chi-square test's, and its alarm outlasts the contact longer. Measured "
              "from the end of each held poke of 0.5–10 N to the end of its flag, the median is "
              f"{tail_c['static']:.0f} ms (static) and {tail_c['moving']:.0f} ms (moving) for the "
              f"CUSUM against {tail_x['static']:.0f} ms and {tail_x['moving']:.0f} ms for the "
              "chi-square test: both wait for the residual's own decay, and the CUSUM then drains g "
              f"from h to 0 (mean {float(cal['static'].duration(h_s)):.0f} samples under no contact, "
              "from its calibration). The default stays `--detector chi2`; use `--detector "
              "cusum` to catch small persistent contacts (light leaning, a cable) at the same false-alarm "
              "rate. `tests/test_sequential.py` checks both claims on held 0.02 N pokes and the CUSUM's "
              "alarm count at a measurable rate."]
    lines += ["", f"Built in {time.perf_counter() - start:.0f} s{' (quick)' if quick else ''}."]
    (ks, exp, n_s), (km, _, _) = per_hour["static"], per_hour["moving"]
    lines[2:2] = [f"**Headline:** set for one false alarm per hour, the chi-square detector flagged {ks} "
                  f"(static) and {km} (moving) of {n_s:,} contact-free samples each (expected {exp:.2g}), "
                  f"and detects a {smallest.get('static', float('nan')):g} N poke within 20 ms in ≥ 95 % of "
                  f"trials ({smallest.get('moving', float('nan')):g} N on the moving leg)", ""]
    md = out_dir / "detection.md"
    write_text_atomic(md, "\n".join(lines) + "\n")
    return [md, *paths]
