"""Simulator benchmarks (run: python benchmarks/bench_sim.py [--quick]).

1. Real-time factor (simulated s / wall s) per integrator on the 1.5 s paper scenes (floating and
   fixed base); anchor in the same run: the plain-float right-hand side vs the vectorized numpy one.
2. 1,000 static posture-sweep points: sensor readings (estimator.sim.static_readings) + dynamic
   localization (estimator.localization.localize_dynamic), vectorized, against the same work
   looped point by point (target < 1 s).
3. Error against run time for the integrators on one scene (reference Radau rtol 1e-10): table and
   plot written to reports/bench_sim.md and reports/bench_sim_integrators.png.
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def timed(fn, repeat=1):
    best = np.inf
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return best, out


def rhs_anchor():
    from estimator.sim.model import Plant
    from torquebench.scenes import load_scene

    plant = Plant(load_scene(ROOT / "scenes" / "paper_floating_link1.toml").sim)
    y = plant.initial_state(1)
    n = 2000
    t_np, _ = timed(lambda: [plant.rhs(0.7, y) for _ in range(n)])
    t_fast, _ = timed(lambda: [plant.rhs1(0.7, y[0]) for _ in range(n)])
    print(f"RHS per call: numpy-vectorized {1e6 * t_np / n:.0f} µs, plain-float {1e6 * t_fast / n:.0f} µs "
          f"(×{t_np / t_fast:.1f})")


def real_time_factors(quick):
    from estimator.sim import simulate
    from torquebench.scenes import load_scene

    print("\n## Real-time factor, 1.5 s paper scenes (one core; target ≥ 1 with the default BDF)")
    print(f"{'scene':24s} {'integrator':10s} {'wall (s)':>9s} {'RHS evals':>10s} {'RTF':>6s}")
    rows = []
    integrators = [("BDF", {}), ("LSODA", {}), ("Radau", {})] + ([] if quick else
                                                                 [("RK45", {}), ("RK4", {"fixed_step_s": 5e-5})])
    for name in ("paper_floating_link1", "paper_fixed_link1"):
        cfg = load_scene(ROOT / "scenes" / f"{name}.toml").sim
        for integ, kw in integrators:
            res = simulate(replace(cfg, integrator=integ, **kw))
            s = res.stats
            rows.append((name, integ, s["run_time_s"], s["rhs_evaluations"], s["real_time_factor"]))
            print(f"{name:24s} {integ:10s} {s['run_time_s']:9.2f} {s['rhs_evaluations']:10d} "
                  f"{s['real_time_factor']:6.2f}")
    return rows


def sweep_batch(n_points=1000):
    from estimator.localization import localize_dynamic
    from estimator.robot import paper_leg
    from estimator.sim import static_readings

    leg = paper_leg(floating=False)
    rng = np.random.default_rng(0)
    q = rng.uniform(0, np.pi, (n_points, 2))
    link = rng.integers(1, 3, n_points)
    alpha = rng.choice([0.25, 0.5, 0.75, 1.0], n_points)
    F = 7.0 * np.array([np.cos(-np.pi / 3), np.sin(-np.pi / 3)])
    qf = np.concatenate([np.zeros((n_points, 3)), q], 1)

    def batch():
        tau, W = static_readings(leg, q, link, alpha, F)
        from estimator import dynamics as dyn
        G = dyn.gravity_vector(leg.with_base(True), qf)
        r = G - np.concatenate([W, tau], 1)          # static: τ_ext = G − τ_meas
        return localize_dynamic(leg, qf, r)

    def looped():
        out = []
        for i in range(n_points):
            tau, W = static_readings(leg, q[i:i + 1], link[i:i + 1], alpha[i:i + 1], F)
            from estimator import dynamics as dyn
            G = dyn.gravity_vector(leg.with_base(True), qf[i:i + 1])
            out.append(localize_dynamic(leg, qf[i:i + 1], G - np.concatenate([W, tau], 1)))
        return out

    t_b, res = timed(batch, repeat=3)
    t_l, _ = timed(looped)
    ok = res.reason == 0
    from estimator import dynamics as dyn
    pt = np.array([dyn.contact_point(leg.with_base(True), qf[i], link[i], alpha[i]) for i in range(n_points)])
    err = np.hypot(*(res.point_m - pt).T)[ok]
    print(f"\n## {n_points} static sweep points (readings + localization), noise-free")
    print(f"vectorized {t_b * 1e3:.1f} ms (target < 1000 ms); looped per point {t_l * 1e3:.0f} ms "
          f"(×{t_l / t_b:.0f}); max location error of the {ok.sum()} well-conditioned points "
          f"{err.max():.2e} m; {(~ok).sum()} flagged")
    return t_b, t_l


def error_vs_time(quick):
    from estimator.sim import simulate
    from torquebench.reports.reproduction import stiffness_cases

    scenes, _ = stiffness_cases(quick=True)
    cfg = replace(next(iter(scenes.values())), duration_s=0.5)
    cfg = replace(cfg, pokes=(replace(cfg.pokes[0], t_on_s=0.2, t_off_s=0.45),))
    ref = simulate(replace(cfg, integrator="Radau", rtol=1e-10, atol=1e-12))
    rows = []
    settings = [(m, {"rtol": r, "atol": r * 1e-2}) for m in ("RK45", "Radau", "BDF", "LSODA")
                for r in ((1e-4, 1e-6) if quick else (1e-4, 1e-6, 1e-8))]
    settings += [("RK4", {"fixed_step_s": h}) for h in ((5e-5,) if quick else (5e-5, 2.5e-5))]
    print("\n## Error against run time (floating paper leg, 7 N poke, 0.5 s; ref Radau rtol 1e-10)")
    print(f"{'integrator':8s} {'setting':>12s} {'wall (s)':>9s} {'max|Δq| rad':>12s} {'max|Δτ| N·m':>12s}")
    for m, kw in settings:
        res = simulate(replace(cfg, integrator=m, **kw))
        dq = float(np.abs(res.q - ref.q).max())
        dt = float(np.abs(res.tau_Nm - ref.tau_Nm).max())
        setting = f"h={kw['fixed_step_s']:g}" if m == "RK4" else f"rtol={kw['rtol']:g}"
        rows.append((m, setting, res.stats["run_time_s"], dq, dt))
        print(f"{m:8s} {setting:>12s} {res.stats['run_time_s']:9.2f} {dq:12.2e} {dt:12.2e}")
    return rows


def write_report(rtf, sweep, evt):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from userio.files import write_text_atomic

    out = ROOT / "reports"
    fig, ax = plt.subplots(figsize=(6.5, 4.5))
    for m in dict.fromkeys(r[0] for r in evt):
        rr = [r for r in evt if r[0] == m]
        ax.loglog([r[2] for r in rr], [max(r[4], 1e-12) for r in rr], "o-", label=m)
    ax.set_xlabel("run time (s)")
    ax.set_ylabel("max |τ − τ_ref| (N·m)")
    ax.set_title("simulator error against run time (paper leg, 0.5 s)")
    ax.legend()
    fig.tight_layout()
    png = out / "bench_sim_integrators.png"
    fig.savefig(png, dpi=110)
    plt.close(fig)
    best = max(rtf, key=lambda r: r[4])
    L = ["# Simulator benchmarks", "", "Generated by `python benchmarks/bench_sim.py`.", "",
         f"**Headline:** the fastest integrator ({best[1]}) simulates the paper's {best[0]} scene at "
         f"{best[4]:.1f}× real time on one core, and the vectorized static sweep is "
         f"{sweep[1] / sweep[0]:.0f}× faster than a Python loop", "",
         "## Real-time factor (1.5 s paper scenes, one core)", "",
         "| scene | integrator | wall (s) | RHS evals | real-time factor |", "|---|---|---|---|---|"]
    L += [f"| {a} | {b} | {c:.2f} | {d} | {e:.2f} |" for a, b, c, d, e in rtf]
    L += ["", f"## 1,000 static sweep points: vectorized {1e3 * sweep[0]:.1f} ms, looped {1e3 * sweep[1]:.0f} ms "
          f"(×{sweep[1] / sweep[0]:.0f})", "", "## Error against run time", "",
          "| integrator | setting | wall (s) | max \\|Δq\\| (rad) | max \\|Δτ\\| (N·m) |", "|---|---|---|---|---|"]
    L += [f"| {a} | {b} | {c:.2f} | {d:.1e} | {e:.1e} |" for a, b, c, d, e in evt]
    L += ["", f"![error vs time]({png.name})", ""]
    write_text_atomic(out / "bench_sim.md", "\n".join(L))
    print(f"\nwrote {out / 'bench_sim.md'} and {png}")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true", help="fewer integrators and settings")
    args = ap.parse_args()
    rhs_anchor()
    rtf = real_time_factors(args.quick)
    sweep = sweep_batch()
    evt = error_vs_time(args.quick)
    write_report(rtf, sweep, evt)


if __name__ == "__main__":
    main()
