"""The STL annuli's geometric error, per level: how far the discrete boundary is from the STL, how many
boundary nodes are pending, the goals' shape derivative δJ (flexure.geometry_error), and each goal's
effectivity with and without it (2 |J(u⁺) − J(u_h)| against 2 |J(u⁺) + δJ − J(u_h)|).

    python benchmarks/fem_geometry_error.py [round|thin ...] [--sections N] [--rtol 0.01] [--deep RTOL] [--json OUT]

``--deep RTOL``: the reference is instead a deeper adaptive run on the same STL to RTOL (its last level's
goals; its own estimate reported as the allowance): for a polygon too coarse to share the circle's answer.

Reference: the N-gon's own converged answer. A gauge strain of the round annulus in torsion,
ε = B/r² (B = T/(4π μ t)), does not depend on the radii a, b, so a polygon whose sides are on average
c = π²/(3N²) of the radius inside the circle (its area) has the circle's strains to first order (its
N-fold ripple decays as (r_in/r)^N away from the bore); its stiffness k ∝ 1/(1/a² − 1/b²) is the
circle's × (1 − c)².
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
sys.path.insert(0, str(ROOT / "benchmarks"))


def run(part: str, sections: int, rtol: float, deep: float | None = None) -> dict:
    """``part``: an annulus of fem_annulus.PARTS as an N-gon STL, or a design file (.toml: needs ``deep``)."""
    from fem_annulus import PARTS, make_part, stiffness_exact

    from flexure.adaptive import ARM_SIGN, ENRICHED_FACTOR, analyze_adaptive
    from flexure.design import load_design
    from flexure.exact import annulus_gauge_exact

    with tempfile.TemporaryDirectory() as tmp:
        if part.endswith(".toml"):
            d = load_design(Path(part))
            exact, k_ref = np.full(len(d.gauges), np.nan), np.nan
        else:
            d = make_part(Path(tmp), part, "stl", sections=sections)
            exact = annulus_gauge_exact(d, thickness_m=PARTS[part]["t"] * 1e-3)
            c = math.pi ** 2 / (3 * sections ** 2)
            k_ref = stiffness_exact(part, d.material.shear_modulus_Pa) * (1 - c) ** 2
        t0 = time.perf_counter()
        res, _ = analyze_adaptive(d, rtol=rtol)
        wall = time.perf_counter() - t0
        s = np.array([ARM_SIGN[g.arm] for g in d.gauges])
        allowance = None
        if deep is not None:
            last = analyze_adaptive(d, rtol=deep)[0]["discretization_levels"][-1]
            k_ref = last["torsional_stiffness_Nm_per_rad"]
            exact = np.array(last["gauge_strains"])
            e = last["estimate"]
            allowance = {"dofs": last["dofs"], "k_pct": 100 * e["torsional_stiffness_Nm_per_rad"] / k_ref,
                         "arms_pct": (100 * np.array(e["gauge_strains"]) / np.abs(exact)).tolist(),
                         "bridge_pct": 100 * e["gauge_strain_per_Nm"] / abs(s @ exact / 4)}
    rows = []
    for lv in res["discretization_levels"]:
        g = lv["geometry"].get("error", {})
        en = lv["enriched"]
        theta = lv["theta"]
        J = np.r_[theta, lv["gauge_strains"], lv["gauge_strain_per_Nm"]]
        ref = np.r_[1.0 / k_ref, exact, s @ exact / 4]
        dis = np.r_[en["theta"], en["gauges"], en["eps_ref"]]
        geo = np.r_[g.get("theta", 0.0), g.get("gauges", [0.0] * len(exact)), g.get("eps_ref", 0.0)]
        true = ref - J
        scale = np.abs(ref)
        rows.append({"level": lv["level"], "dofs": lv["dofs"], "pending": lv["pending_nodes"],
                     "offsets": g.get("offsets"), "geometry_marked": g.get("marked"),
                     "true_pct": (100 * true / scale).tolist(), "disc_pct": (100 * dis / scale).tolist(),
                     "geo_pct": (100 * geo / scale).tolist(),
                     "eff_before": (ENRICHED_FACTOR * np.abs(dis) / np.abs(true)).tolist(),
                     "eff_after": (ENRICHED_FACTOR * np.abs(dis + geo) / np.abs(true)).tolist(),
                     "geometry_s": lv["geometry"].get("s")})
    return {"part": part, "sections": sections, "rtol": rtol, "wall_s": wall, "stopped_by": res["stopped_by"],
            "reference": "deep" if deep else "polygon", "allowance": allowance,
            "levels": rows, "load": float(open("/proc/loadavg").read().split()[0])}


def show(r: dict) -> None:
    f = lambda xs, p=3: ", ".join(f"{x:+.{p}f}" for x in xs)  # noqa: E731
    print(f"## {r['part']} {r['sections']}-gon STL, rtol {r['rtol']}: {r['wall_s']:.0f} s, {r['stopped_by']}, "
          f"load {r['load']:.1f}  (goals: θ, arms 1-4, bridge; reference {r['reference']} {r['allowance'] or ''})")
    for x in r["levels"]:
        o = x["offsets"] or {}
        um = lambda k: f"{1e6 * o[k]['max']:.2f}/{1e6 * o[k]['median']:.3f}" if k in o else "-"  # noqa: E731
        print(f"L{x['level']} {x['dofs']} dofs, pending {x['pending']}, geometry-marked {x['geometry_marked']}, "
              f"offsets max/median µm: quad {um('quad_points_m')} vert {um('vertices_m')} mid {um('mid_nodes_m')}"
              f" ({x['geometry_s']:.1f} s)")
        print(f"   true%  [{f(x['true_pct'])}]\n   disc%  [{f(x['disc_pct'])}]\n   geo%   [{f(x['geo_pct'], 4)}]")
        print(f"   eff before [{', '.join(f'{e:.2f}' for e in x['eff_before'])}]\n"
              f"   eff after  [{', '.join(f'{e:.2f}' for e in x['eff_after'])}]", flush=True)


def main(argv):
    rtol, out, sections, parts, deep = 0.01, None, 192, [], None
    it = iter(argv)
    for a in it:
        if a == "--rtol":
            rtol = float(next(it))
        elif a == "--sections":
            sections = int(next(it))
        elif a == "--deep":
            deep = float(next(it))
        elif a == "--json":
            out = next(it)
        else:
            parts.append(a)
    res = []
    for p in parts or ["round", "thin"]:
        r = run(p, sections, rtol, deep)
        show(r)
        res.append(r)
    if out:
        Path(out).write_text(json.dumps(res, indent=1))


if __name__ == "__main__":
    main(sys.argv[1:])
