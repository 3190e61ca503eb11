"""Per-level effectivity of the adaptive estimate against an exact reference: annuli in torsion.

    python benchmarks/fem_annulus.py [round_stl|round_step|thin_stl|thin_step ...] [--rtol 0.01] [--json OUT]
                                     [--exact-bands]

``--exact-bands``: the load and clamp sets are the bore and rim faces alone (radius bands within
0.5 µm of them), so the torsion field is the exact solution of the discrete problem (on a STEP part;
an STL's is a polygon); by default the bands also take 0.02/0.1 mm rings of the faces, which moves
the read-outs by up to ~0.02 % from the exact field.

A round annulus (r a … b, thickness t, rigid bore, clamped rim) under a torque about its axis
carries u_θ = B/r − B r/b² whatever a, b and t (free faces traction-free), so every gauge's read-out
is known in closed form (flexure.exact.annulus_gauge_exact). Two parts:

* ``round``: r 3 … 10 mm, 3 mm thick, four ±45° 2 × 2 mm gauges at r = 6.5 mm (the test's part);
* ``thin``: r 5 … 18 mm, 1.2 mm thick, four 1.5 × 1 mm gauges at r = 8, 9.5, 11, 12.5 mm, at
  angles 17°, 131°, 208°, 303°, axes 30°, 55°, −40°, −65° off the radial (no symmetry between them).

Each as an STL (a polygon of 192 sides, trimesh) and as a STEP (gmsh OpenCASCADE cylinders: the
exact circles). Prints, per level, each arm's signed true error, its estimate and the effectivity.
"""

from __future__ import annotations

import json
import math
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from flexure.exact import annulus_gauge_exact  # noqa: E402

PARTS = {
    "round": dict(r_in=3.0, r_out=10.0, t=3.0, load_max=3.02, fixed_min=9.9, grid=(2.0, 2.0),
                  gauges=[(6.5, a, (45.0 if k % 2 == 0 else -45.0)) for k, a in enumerate((0.0, 90.0, 180.0, 270.0))]),
    "thin": dict(r_in=5.0, r_out=18.0, t=1.2, load_max=5.02, fixed_min=17.9, grid=(1.5, 1.0),
                 gauges=[(8.0, 17.0, 30.0), (9.5, 131.0, 55.0), (11.0, 208.0, -40.0), (12.5, 303.0, -65.0)]),
}

TOML = """\
name = "{name}"
[geometry]
kind = "{kind}"
file = "{file}"
[gauges]
grid_length_mm = {gl}
grid_width_mm = {gw}
{gauges}
[loads]
rated_torque_Nm = 2.0
load_radius_max_mm = {load_max}
fixed_radius_min_mm = {fixed_min}
[mesh]
size = "coarse"
order = 2
"""


def make_part(folder: Path, part: str, kind: str, sections: int = 192, exact_bands: bool = False):
    """Write the part's geometry (STL or STEP) and design; → the loaded design."""
    from flexure.design import load_design

    p = PARTS[part]
    if kind == "stl":
        import trimesh

        tm = trimesh.creation.annulus(r_min=p["r_in"], r_max=p["r_out"], height=p["t"], sections=sections)
        tm.apply_translation((0, 0, p["t"] / 2))
        tm.export(folder / f"{part}.stl")
        file = f"{part}.stl"
    else:
        import gmsh

        gmsh.initialize(interruptible=False)
        try:
            gmsh.option.setNumber("General.Terminal", 0)
            gmsh.model.add(part)
            o = gmsh.model.occ.addCylinder(0, 0, 0, 0, 0, p["t"], p["r_out"])
            i = gmsh.model.occ.addCylinder(0, 0, 0, 0, 0, p["t"], p["r_in"])
            gmsh.model.occ.cut([(3, o)], [(3, i)])
            gmsh.model.occ.synchronize()
            gmsh.write(str(folder / f"{part}.step"))
        finally:
            gmsh.finalize()
        file = f"{part}.step"
    gauges = []
    for arm, (r, ang, off) in enumerate(p["gauges"], start=1):
        a = math.radians(ang)
        c = (r * math.cos(a), r * math.sin(a), p["t"])
        ax = (math.cos(a + math.radians(off)), math.sin(a + math.radians(off)), 0.0)
        gauges.append(f"[[gauges.gauge]]\ncentre_mm = [{c[0]:.6f}, {c[1]:.6f}, {c[2]:.6f}]\n"
                      f"axis = [{ax[0]:.9f}, {ax[1]:.9f}, 0.0]\narm = {arm}")
    (folder / f"{part}.toml").write_text(TOML.format(
        name=f"{part}_{kind}", kind=kind, file=file, gl=p["grid"][0], gw=p["grid"][1], gauges="\n".join(gauges),
        load_max=p["r_in"] + 5e-4 if exact_bands else p["load_max"],
        fixed_min=p["r_out"] - 5e-4 if exact_bands else p["fixed_min"]))
    return load_design(folder / f"{part}.toml")


def stiffness_exact(part: str, shear_modulus_Pa: float) -> float:
    """k = 4π μ t / (1/a² − 1/b²) of the round annulus in torsion (N·m/rad)."""
    p = PARTS[part]
    a, b, t = p["r_in"] * 1e-3, p["r_out"] * 1e-3, p["t"] * 1e-3
    return 4.0 * math.pi * shear_modulus_Pa * t / (1.0 / a**2 - 1.0 / b**2)


def run(name: str, rtol: float, exact_bands: bool = False) -> dict:
    from flexure.adaptive import analyze_adaptive

    part, kind = name.split("_")
    with tempfile.TemporaryDirectory() as tmp:
        d = make_part(Path(tmp), part, kind, exact_bands=exact_bands)
        exact = annulus_gauge_exact(d, thickness_m=PARTS[part]["t"] * 1e-3)
        k_ex = stiffness_exact(part, d.material.shear_modulus_Pa)
        t0 = time.perf_counter()
        res, _ = analyze_adaptive(d, rtol=rtol)
        wall = time.perf_counter() - t0
    rows = []
    for lv in res["discretization_levels"]:
        got = np.array(lv["gauge_strains"])
        est = np.array(lv["estimate"]["gauge_strains"])
        true = got - exact
        k = lv["torsional_stiffness_Nm_per_rad"]
        ek = lv["estimate"]["torsional_stiffness_Nm_per_rad"]
        sgn = np.array([1.0, -1.0, 1.0, -1.0])
        b_ex = float(sgn @ exact / 4.0)
        b_true = lv["gauge_strain_per_Nm"] - b_ex
        eb = lv["estimate"]["gauge_strain_per_Nm"]
        rows.append({"level": lv["level"], "dofs": lv["dofs"], "true_pct": (100 * true / np.abs(exact)).tolist(),
                     "est_pct": (100 * est / np.abs(exact)).tolist(), "eff": (est / np.abs(true)).tolist(),
                     "k_true_pct": 100 * (k - k_ex) / k_ex, "k_est_pct": 100 * ek / k_ex, "k_eff": ek / abs(k - k_ex),
                     "bridge_true_pct": 100 * b_true / abs(b_ex), "bridge_est_pct": 100 * eb / abs(b_ex),
                     "bridge_eff": eb / abs(b_true), "enriched_s": lv.get("enriched_s"),
                     "level_s": lv.get("level_s"), "solve_s": lv.get("solve_s"), "dwr_s": lv.get("dwr_s"),
                     "refine_s": lv.get("refine_s"), "geom": lv.get("geometry"),
                     "eta_pct": None if lv["eta"] is None else (100 * np.array(lv["eta"]["gauges"]) / np.abs(exact)).tolist(),
                     "kappa": lv.get("kappa"),
                     "record": {k: lv.get(k) for k in ("level", "dofs", "theta", "torsional_stiffness_Nm_per_rad",
                                                       "gauge_strain_per_Nm", "gauge_strains", "enriched",
                                                       "geometry", "goal_algebraic_error", "q_unmeasured")}})
    return {"name": name, "rtol": rtol, "exact_bands": exact_bands, "wall_s": wall, "exact_gauges": exact.tolist(),
            "exact_stiffness": k_ex, "stopped_by": res["stopped_by"],
            "peak_rss_gb": res["discretization_levels"][-1].get("peak_rss_gb"), "levels": rows,
            "load": float(open("/proc/loadavg").read().split()[0])}


def show(r: dict) -> None:
    f = lambda xs: ", ".join(f"{x:+.3f}" for x in xs)  # noqa: E731
    print(f"## {r['name']} rtol {r['rtol']}: {r['wall_s']:.0f} s, stopped by {r['stopped_by']}, "
          f"peak {r['peak_rss_gb']:.2f} GB, load {r['load']:.1f}")
    for x in r["levels"]:
        print(f"L{x['level']} {x['dofs']:>7} true% [{f(x['true_pct'])}] est% [{f(x['est_pct'])}] "
              f"eff [{', '.join(f'{e:.2f}' for e in x['eff'])}] | k true {x['k_true_pct']:+.3f}% est {x['k_est_pct']:.3f}% "
              f"eff {x['k_eff']:.2f} | bridge true {x['bridge_true_pct']:+.3f}% est {x['bridge_est_pct']:.3f}% "
              f"eff {x['bridge_eff']:.2f} | {x['level_s']:.1f} s (solve {x['solve_s']:.1f}, "
              f"enriched {x['enriched_s'] or 0:.1f}, dwr {x['dwr_s'] or 0:.1f}, "
              f"refine {x['refine_s'] or 0:.1f}) geom {x['geom']}", flush=True)


def main(argv: list[str]) -> None:
    rtol, out, names, exact_bands = 0.01, None, [], False
    it = iter(argv)
    for a in it:
        if a == "--rtol":
            rtol = float(next(it))
        elif a == "--exact-bands":
            exact_bands = True
        elif a == "--json":
            out = next(it)
        else:
            names.append(a)
    results = []
    for n in names or ["round_stl", "round_step", "thin_stl"]:
        r = run(n, rtol, exact_bands)
        show(r)
        results.append(r)
    if out:
        Path(out).write_text(json.dumps(results, indent=1, default=lambda o: o.tolist() if hasattr(o, "tolist") else str(o)))


if __name__ == "__main__":
    main(sys.argv[1:])
