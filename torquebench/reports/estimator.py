"""reports/estimator.md: the estimator on the independent leg_poke log and on a moving leg.

Figures: the observer residual of leg_poke.csv (the detection statistic with its threshold, the
force rows in N and the moment rows in N·m on separate axes) and the estimated
α/F against the truth; the position error of `paper` vs `dynamic` on a leg swinging under a
constant poke (built by inverse dynamics). Numbers are measured when the report is built.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from torquebench.io import REPO_ROOT
from userio.files import atomic_path, write_text_atomic

SAMPLES = REPO_ROOT / "examples" / "leg_poke"


def _save(fig, path: Path) -> Path:
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=110, format="png")
    return path


def _leg_poke(out_dir: Path, lines: list[str]) -> list[Path]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import pandas as pd

    from estimator.log_reader import read_log
    from estimator.estimate import estimate
    from estimator.robot import paper_leg

    log_path = SAMPLES / "leg_poke.csv"
    if not log_path.exists():
        lines += ["", f"(leg_poke.csv not found at {log_path}; section skipped)"]
        return []
    robot = paper_leg()
    log = read_log(log_path, robot)
    truth = pd.read_csv(SAMPLES / "leg_poke.truth.csv")
    F_true = 3.0 * np.array([np.cos(2.0), np.sin(2.0)])
    on = (log.t >= 0.5) & (log.t < 0.9)
    rows = []
    ests = {}
    worst = {}                                         # method → (max F error N, max point error m)
    estimate(robot, log, method="dynamic")            # warm-up: imports, caches
    for method in ("dynamic", "paper"):
        start = time.perf_counter()
        est = estimate(robot, log, method=method)
        elapsed = time.perf_counter() - start
        ests[method] = est
        a_err = np.nanmax(np.abs(est.alpha[on] - 0.4))
        f_err = np.nanmax(np.hypot(est.Fx[on] - F_true[0], est.Fz[on] - F_true[1]))
        p_err = np.nanmax(np.hypot(est.px[on] - truth.px[on], est.pz[on] - truth.pz[on]))
        iv = est.intervals()[0]
        worst[method] = (f_err, p_err)
        rows.append(f"| {method} | {iv['t_start_s']:.3f}–{iv['t_end_s']:.3f} | {iv['link']} | "
                    f"{a_err:.1e} | {f_err:.1e} | {1e3 * p_err:.3f} | {1e3 * elapsed:.0f} |")
    (fd, pd_), (fp, pp) = worst["dynamic"], worst["paper"]
    lines[2:2] = [f"**Headline:** on an independent MuJoCo log (3 N on link 2), the `dynamic` localization "
                  f"places the contact within {1e3 * pd_:.3g} mm and the force within {fd:.2g} N of the truth "
                  f"once the observer has converged (the paper's method: {1e3 * pp:.3g} mm, {fp:.2g} N)", ""]
    lines += ["", "## leg_poke.csv (independent MuJoCo log, 3 N on link 2 at α = 0.4, 0.4–0.9 s)", "",
              "Errors are maxima over t ∈ [0.5, 0.9) s (after the observer has converged, 10/K).", "",
              "| method | detected interval (s) | link | max abs α error | max F error (N) | max point error (mm) | run time (ms) |",
              "|---|---|---|---|---|---|---|", *rows, "",
              "![leg_poke residual](estimator_leg_poke.png)"]
    from torquebench.scene_views import draw_residual

    est = ests["dynamic"]
    fig, ax = plt.subplots(5, 1, figsize=(8, 12), sharex=True)
    draw_residual(ax[:3], est, robot)          # ‖r‖, the force rows (N), the moment rows (N·m)
    ax[0].set_title("leg_poke.csv: momentum-observer residual (K = 100 s⁻¹)")
    ax = ax[2:]                                # α and F below
    for method, style in (("dynamic", "-"), ("paper", ":")):
        e = ests[method]
        ax[1].plot(e.t, e.alpha, style, label=f"α {method}")
        ax[2].plot(e.t, e.Fx, style, label=f"Fx {method}")
        ax[2].plot(e.t, e.Fz, style, label=f"Fz {method}")
    ax[1].plot(truth.t, truth.alpha, "k", lw=0.8, label="truth")
    ax[1].set_ylabel("α")
    ax[1].legend(fontsize=8)
    ax[2].plot(truth.t, truth.Fx, "k", lw=0.8)
    ax[2].plot(truth.t, truth.Fz, "k", lw=0.8, label="truth")
    ax[2].set_ylabel("F (N)")
    ax[2].set_xlabel("t (s)")
    ax[2].legend(fontsize=8, ncol=3)
    fig.tight_layout()
    path = _save(fig, out_dir / "estimator_leg_poke.png")
    plt.close(fig)
    return [path]


def _moving(out_dir: Path, lines: list[str]) -> list[Path]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from estimator.estimate import estimate
    from estimator.robot import paper_leg
    from estimator.synthetic import moving_leg_poke

    robot = paper_leg()
    K = 100.0
    fig, ax = plt.subplots(figsize=(8, 4))
    rows = []
    for freq in (0.5, 1.0, 2.0):
        log, truth = moving_leg_poke(robot, duration_s=3.0, frequency_Hz=freq, t_on_s=0.5,
                                     base_amplitude=(0.01, 0.01, 0.05))
        settled = log.t > 0.5 + 5 / K
        errs = {}
        for method in ("dynamic", "paper"):
            est = estimate(robot, log, method=method, gain_per_s=K)
            e = np.hypot(est.px - truth.point_m[:, 0], est.pz - truth.point_m[:, 1])
            errs[method] = e
            if freq == 1.0:
                ax.plot(log.t, 1e3 * e, label=method)
        for method, e in errs.items():
            s = e[settled]
            rows.append(f"| {freq:g} | {method} | {1e3 * np.nanmedian(s):.2f} | {1e3 * np.nanmax(s):.2f} | "
                        f"{np.isfinite(s).mean():.3f} |")
    ax.axhline(5, color="r", lw=0.8, label="5 mm")
    ax.set_yscale("log")
    ax.set_xlabel("t (s)")
    ax.set_ylabel("position error (mm)")
    ax.set_title("leg swinging at 1 Hz (base swaying), constant 5 N poke on link 2 from 0.5 s")
    ax.legend()
    fig.tight_layout()
    path = _save(fig, out_dir / "estimator_moving_leg.png")
    plt.close(fig)
    lines += ["", "## Moving leg: `paper` (quasi-static) vs `dynamic`", "",
              "Paper leg, joints q = q0 + A sin(2π f t + φ) (A = 0.35, 0.3 rad), base swaying "
              "(1 cm, 1 cm, 0.05 rad), a constant 5 N poke at −π/3 on link 2, α = 0.5 from t = 0.5 s; "
              "log built by inverse dynamics (no simulator), 1 kHz, noise-free. Errors after 0.55 s (5/K).",
              "", "| f (Hz) | method | median error (mm) | max error (mm) | answered fraction |",
              "|---|---|---|---|---|", *rows, "", "![moving leg](estimator_moving_leg.png)", "",
              "`paper` reads the base's and links' inertial forces M q̈ as contact force (eqs. 6–9 are "
              "quasi-static); `dynamic` uses the observer residual, which removes them, and pairs r(t) "
              "with the posture q(t − 1/K) to undo the observer's lag."]
    return [path]


def _speed(lines: list[str]) -> None:
    from estimator.observer import MomentumObserver, residual_offline
    from estimator.localization import localize_dynamic
    from estimator.robot import paper_leg
    from estimator.synthetic import moving_leg_poke

    robot = paper_leg()
    n = 200_000
    log, _ = moving_leg_poke(robot, duration_s=n / 1000, t_on_s=0.0)
    residual_offline(robot, log.t[:10], log.q[:10], log.dq[:10], log.tau_meas[:10])
    start = time.perf_counter()
    r = residual_offline(robot, log.t, log.q, log.dq, log.tau_meas, 100.0)
    localize_dynamic(robot, log.q, r)
    rate = n / (time.perf_counter() - start)
    obs = MomentumObserver(robot, 1e-3)
    q, dq, tau = log.q, log.dq, log.tau_meas          # tau_meas is assembled on access: once
    lat = []
    for k in range(5000):
        t0 = time.perf_counter_ns()
        obs.step(q[k], dq[k], tau[k])
        lat.append(time.perf_counter_ns() - t0)
    lines += ["", "## Speed (measured while building this report; see `python benchmarks/bench_estimator.py`)", "",
              f"- offline observer + dynamic localization: {rate:,.0f} samples/s on {n:,} samples "
              f"(target ≥ 1,000,000 samples/s on one core)",
              f"- streaming `step()`: median {np.median(lat) / 1e3:.1f} µs per sample (target ≤ 50 µs)"]


def build(out_dir: Path) -> list[Path]:
    out_dir = Path(out_dir)
    lines = ["# Estimator: momentum observer, detection, isolation, localization", "",
             "Conventions: forces ON the robot, M q̈ + C q̇ + G = τ + Jᵀ F; residual r → τ_ext with "
             "r-dynamics ṙ = K (τ_ext − r), exact (exponential) discretization, K = 100 s⁻¹, ε_res = 0.06. "
             "Both methods recover noise-free static contacts on every link to < 1e-6 (tests/test_localization.py)."]
    paths = _leg_poke(out_dir, lines)
    paths += _moving(out_dir, lines)
    _speed(lines)
    md = out_dir / "estimator.md"
    write_text_atomic(md, "\n".join(lines) + "\n")
    return [md, *paths]
