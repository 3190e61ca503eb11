"""`torquebench compare SCENE.toml --vary flexure=a.toml,b.toml`: designs end to end.

Each value of the varied key (any dotted scene key) runs the scene's stage graph (torquebench.sweep);
per variant: sensitivity, torsional stiffness and safety factor (when the scene has a flexure
design), torque noise, and the predicted (Monte Carlo) and simulated localization error.
"""

from __future__ import annotations

import math
from pathlib import Path

HELP = "compare designs (or any scene key) end to end: sensitivity, stiffness, noise, localization error"
EXAMPLES = """\
torquebench compare scenes/end_to_end.toml --vary flexure=5e-5,5e-4 --png out/compare.png
"""


def add_arguments(parser) -> None:
    parser.add_argument("scene", type=Path, help="scene TOML (e.g. scenes/end_to_end.toml)")
    parser.add_argument("--vary", action="append", required=True, metavar="KEY=V1,V2",
                        help="dotted scene key and its values; for designs flexure=a.toml,b.toml (each value a design file "
                             "or a strain per N·m, e.g. flexure=5e-5,5e-4)")
    parser.add_argument("--executor", default="local", help="local (default), processes:N, dask://HOST:PORT")
    parser.add_argument("--png", type=Path, default=None,
                        help="write a bar chart of the comparison (directory created; an existing "
                             "file is kept unless --force)")
    parser.add_argument("--force", action="store_true", help="replace an existing --png file")
    parser.add_argument("--cache-dir", type=Path, default=None, help="cache directory")


#: the flexure's figures a comparison carries with their error estimates (flexure.convergence)
DESIGN_FIGURES = ("sensitivity_mV_per_V_per_Nm", "torsional_stiffness_Nm_per_rad", "safety_factor",
                  "min_detectable_torque_Nm")


def row(r: dict) -> dict:
    """One comparison row from a sweep point."""
    if "error" in r:
        return {"point": r["point"], "error": r["error"]}
    res = r["result"]
    fx, s = res.get("flexure", {}), res.get("sensor", {})
    pr = res.get("predicted", {}).get("dynamic", {})
    me = res.get("measured", {}).get("dynamic", {})
    out = {"point": r["point"], "sensitivity_V_per_Nm": s.get("sensitivity_V_per_Nm")}
    for key in DESIGN_FIGURES:                  # the FEM's figures, each with its ± and how
        for suffix in ("", "_error_estimate", "_error_method"):
            out[key + suffix] = fx.get(key + suffix)
    out["crosstalk_max_percent"] = fx.get("crosstalk_max_percent")
    return {**out,
            "torque_noise_std_Nm": s.get("torque_noise_std_Nm"),
            "predicted_position_rms_m": pr.get("position_rms_m"),
            "predicted_position_rms_m_error_estimate": pr.get("position_rms_m_error_estimate"),
            "predicted_position_rms_m_error_method": pr.get("position_rms_m_error_method"),
            "simulated_position_rms_m": me.get("position_error_rms_m")}


def run(args) -> int:
    from torquebench.outputs import scene_plan
    from torquebench.scenes import load_scene, scene_path
    from torquebench.sweep import parse_vary, run_sweep

    path = scene_path(str(args.scene))
    vary = parse_vary(args.vary)
    plan = scene_plan(load_scene(path), force=args.force)     # the scene and every file it reads
    for key, values in vary:                                 # varied files (a design per variant)
        for v in values:
            for cand in (Path(str(v)), path.parent / str(v)):
                if isinstance(v, str) and cand.is_file():
                    plan.input(f"--vary {key}", cand)
    plan.file("--png", args.png)
    with plan.active():                                      # checked before the points run
        rows = [row(r) for r in run_sweep(path, vary, None, args.executor,
                                          str(args.cache_dir) if args.cache_dir else None,
                                          progress=not args.json)]
        return _report(args, path, rows)


def _report(args, path, rows) -> int:
    from torquebench.commands.sweep import _exit_on_failures
    from torquebench.io import print_json

    out = {"scene": str(path), "rows": rows}
    if args.png and any("error" not in r for r in rows):
        _plot(args.png, rows)
        out["png"] = str(args.png)
    if args.json:
        print_json(out)
        _exit_on_failures(rows, "compare")
        return 0
    f = (lambda v, k=1.0, d=3: "—" if v is None or (isinstance(v, float) and math.isnan(v))   # noqa: E731
         else f"{v * k:.{d}g}")

    def pm(r, key, k=1.0, d=3):                 # value ± its error estimate
        v, e = r.get(key), r.get(f"{key}_error_estimate")
        return f(v, k, d) + ("" if e is None or v is None or not math.isfinite(e) else f"±{f(e, k, 2)}")

    print(f"{'variant':26s} {'mV/V/N·m':>15s} {'N·m/rad':>13s} {'SF':>10s} {'τ_min mN·m':>12s} "
          f"{'x-talk %':>8s} {'σ_τ N·m':>8s} {'pred. mm':>12s} {'sim. mm':>7s}")
    for r in rows:
        name = ", ".join(f"{k}={v}" for k, v in r["point"].items())[:26]
        if "error" in r:
            print(f"{name:26s} FAILED: {r['error']}")
            continue
        print(f"{name:26s} {pm(r, 'sensitivity_mV_per_V_per_Nm'):>15s} "
              f"{pm(r, 'torsional_stiffness_Nm_per_rad', d=4):>13s} {pm(r, 'safety_factor'):>10s} "
              f"{pm(r, 'min_detectable_torque_Nm', 1e3):>12s} {f(r['crosstalk_max_percent'], 1, 2):>8s} "
              f"{f(r['torque_noise_std_Nm']):>8s} {pm(r, 'predicted_position_rms_m', 1e3):>12s} "
              f"{f(r['simulated_position_rms_m'], 1e3):>7s}")
    _exit_on_failures(rows, "compare")
    return 0


def _plot(path: Path, rows: list[dict]) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    from userio.files import atomic_path

    ok = [r for r in rows if "error" not in r]
    names = [", ".join(str(v) for v in r["point"].values()) for r in ok]
    x = np.arange(len(ok))
    val = lambda k: np.array([r.get(k) if r.get(k) is not None else np.nan for r in ok], float)  # noqa: E731
    panels = [("sensitivity_mV_per_V_per_Nm", 1.0, "sensitivity [mV/V per N·m]"),
              ("torsional_stiffness_Nm_per_rad", 1.0, "torsional stiffness [N·m/rad]"),
              ("safety_factor", 1.0, "safety factor at rated torque [-]"),
              ("min_detectable_torque_Nm", 1e3, "minimum detectable torque (1σ) [mN·m]")]
    panels = [p for p in panels if np.isfinite(val(p[0])).any()]
    cols = (len(panels) + 3) // 2
    fig, grid = plt.subplots(2, cols, figsize=(4 * cols, 7), constrained_layout=True, squeeze=False)
    axes = list(grid.ravel())
    for ax in axes[len(panels):-2]:
        ax.set_visible(False)
    for ax, (key, k, label) in zip(axes, panels):
        ax.bar(x, val(key) * k, yerr=val(f"{key}_error_estimate") * k, capsize=4)
        ax.set(xticks=x, xticklabels=names, ylabel=label)
    a, b = axes[-2], axes[-1]
    a.bar(x - 0.2, val("predicted_position_rms_m") * 1e3, 0.4,
          yerr=val("predicted_position_rms_m_error_estimate") * 1e3, capsize=4, label="predicted (MC, ±1σ)")
    a.bar(x + 0.2, val("simulated_position_rms_m") * 1e3, 0.4, label="simulated")
    a.set(xticks=x, xticklabels=names, ylabel="contact position RMS error [mm]")
    a.legend()
    b.bar(x, val("torque_noise_std_Nm"))
    b.set(xticks=x, xticklabels=names, ylabel="torque noise σ_τ [N·m]")
    with atomic_path(path) as tmp:                      # the output plan decides (--force)
        fig.savefig(tmp, format="png", dpi=100)
    plt.close(fig)
