"""Adaptive (goal-oriented) FEM runs for references and effectivity measurements.

    python benchmarks/fem_adaptive.py deep NAME [NAME ...]   # run each design deep, save its levels
    python benchmarks/fem_adaptive.py refs                   # references from the deep runs → JSON

``deep``: flexure.adaptive.analyze_adaptive with a tight --rtol and large budgets; every level's
goals (stiffness, bridge strain, each arm) and raw/calibrated estimates go to
tests/data/fem_reference/adaptive/NAME.json. The levels are nested, so a goal converges smoothly:
the reference of a figure Q is the geometric extrapolation of its last three levels (of J⁺ = J(u⁺), the
enriched solution's value, where the levels carry it: ``reference``),

    Q∞ = Q_L + (Q_L − Q_(L−1)) ρ/(1 − ρ),   ρ = (Q_L − Q_(L−1))/(Q_(L−1) − Q_(L−2)),

used only where 0 < ρ < 1 (monotone convergence); the allowance is |Q∞ − Q_L| (the
extrapolation's whole size), or, where ρ is not in (0, 1), the last change |Q_L − Q_(L−1)|
around Q_L. Designs: the five reference parts (tests/data/fem_reference) and the unseen parts
(tests/data/fem_unseen, made by benchmarks/fem_unseen_parts.py; held_out/, by fem_held_out_parts.py).
"""

from __future__ import annotations

import json
import math
import os
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / "tests" / "data" / "fem_reference"
OUT = DATA / "adaptive"
DESIGNS = {"paper_disc": ROOT / "designs" / "paper_disc.toml", "reentrant": DATA / "reentrant.toml",
           "step_part": DATA / "step_part.toml", "thick_disc": DATA / "thick_disc.toml",
           "thick_disc_stl": DATA / "thick_disc_stl.toml"}
UNSEEN = ROOT / "tests" / "data" / "fem_unseen"


def design_path(name: str) -> Path:
    """A reference part's design, else an unseen part's (tests/data/fem_unseen, then its held_out/)."""
    if name in DESIGNS:
        return DESIGNS[name]
    p = UNSEEN / f"{name}.toml"
    return p if p.exists() else UNSEEN / "held_out" / f"{name}.toml"


def deep(name: str, rtol: float = 2e-3, max_dofs: int = 700_000, max_memory_gb: float = 8.0,
         growth: float = 2.0) -> dict:
    """One design's adaptive sequence to ``rtol`` (or the budgets), with its wall time. Each level at
    most ``growth`` × the previous one's DOFs (flexure.adaptive_sizing.MAX_GROWTH for this run): a
    sequence of similar steps, so that the errors fall by a similar ratio and extrapolate."""
    from flexure import adaptive_sizing
    from flexure.adaptive import analyze_adaptive
    from flexure.design import load_design

    t0 = time.perf_counter()
    saved, adaptive_sizing.MAX_GROWTH = adaptive_sizing.MAX_GROWTH, growth
    try:
        res, _ = analyze_adaptive(load_design(design_path(name)), rtol=rtol, max_dofs=max_dofs,
                                  max_memory_gb=max_memory_gb, progress=True)
    finally:
        adaptive_sizing.MAX_GROWTH = saved
    keep = ("level", "dofs", "elements", "theta", "torsional_stiffness_Nm_per_rad", "gauge_strain_per_Nm",
            "gauge_strains", "eta", "enriched", "estimate", "kappa", "kappa_how", "min_dihedral_deg", "level_s",
            "peak_rss_gb", "pending_nodes", "goal_algebraic_error", "q_unmeasured")
    return {"design": name, "rtol": rtol, "growth": growth, "stopped_by": res["stopped_by"],
            "wall_s": time.perf_counter() - t0, "load_1min_end": os.getloadavg()[0],
            "how": f"benchmarks/fem_adaptive.py deep {name} (rtol {rtol:g}, ≤ {growth:g}× DOFs per level, "
                   f"max_dofs {max_dofs}, {max_memory_gb:g} GB)",
            "levels": [{k: lv.get(k) for k in keep} for lv in res["discretization_levels"]]}


def extrapolate(values: list[float]) -> dict:
    """Reference and allowance of a nested sequence (module docstring)."""
    q = [float(v) for v in values]
    if len(q) < 3:
        return {"value": q[-1], "allowance": math.inf, "how": "fewer than three levels"}
    d1, d2 = q[-2] - q[-3], q[-1] - q[-2]
    rho = d2 / d1 if d1 != 0 else math.nan
    if 0 < rho < 1:
        lim = q[-1] + d2 * rho / (1 - rho)
        return {"value": lim, "allowance": abs(lim - q[-1]),
                "how": f"geometric extrapolation of the last three nested levels (ratio {rho:.3f}); allowance its size"}
    return {"value": q[-1], "allowance": abs(d2), "how": f"last level ± its last change (ratio {rho:.3g}: not monotone)"}


def _series(lv: list[dict], goal: str, enriched: bool) -> list[float]:
    """A goal's values over the levels: J_h, or J⁺ = J_h + d (d the enriched difference) if ``enriched``."""
    def one(x):
        if goal == "torsional_stiffness_Nm_per_rad":
            return 1.0 / (x["theta"] + x["enriched"]["theta"]) if enriched else x[goal]
        if goal == "gauge_strain_per_Nm":
            return x[goal] + (x["enriched"]["eps_ref"] if enriched else 0.0)
        i = int(goal[5:])
        return x["gauge_strains"][i] + (x["enriched"]["gauges"][i] if enriched else 0.0)
    return [one(x) for x in lv]


def reference(lv: list[dict], goal: str) -> dict:
    """A goal's reference from the nested levels: the extrapolation of J⁺ = J(u⁺) where the levels carry
    the enriched difference (it converges faster than J_h), its allowance the largest of its own size, its
    distance from the extrapolation of J_h (two sequences that must agree) and the last level's enriched
    difference |d_L| (|J − J⁺_L| = q |d_L|/(1 − q) ≤ |d_L| for q ≤ ½); J_h's alone otherwise."""
    h = extrapolate(_series(lv, goal, False))
    if not all(x.get("enriched") for x in lv):
        return h
    p = extrapolate(_series(lv, goal, True))
    d_last = abs(_series(lv[-1:], goal, True)[0] - _series(lv[-1:], goal, False)[0])
    a = max(p["allowance"], abs(p["value"] - h["value"]), d_last)
    return {"value": p["value"], "allowance": a, "how": f"J⁺: {p['how']}; J_h: {h['how']} ({h['value']:.9g}); "
            "allowance the largest of J⁺'s extrapolation, the two limits' distance and the last |d|"}


def references(run: dict) -> dict:
    """Stiffness, bridge strain and each arm's reference from a deep run."""
    lv = run["levels"]
    out = {g: reference(lv, g) for g in ("torsional_stiffness_Nm_per_rad", "gauge_strain_per_Nm")}
    for i in range(len(lv[-1]["gauge_strains"])):
        out[f"gauge{i}"] = reference(lv, f"gauge{i}")
    out["dofs"] = lv[-1]["dofs"]
    return out


def main(argv: list[str]) -> int:
    sys.path.insert(0, str(ROOT))
    OUT.mkdir(parents=True, exist_ok=True)
    if argv and argv[0] == "deep":
        for name in argv[1:]:
            run = deep(name)
            run["references"] = references(run)
            (OUT / f"{name}.json").write_text(json.dumps(run, indent=1) + "\n")
            print(name, run["stopped_by"], f"{run['wall_s']:.0f} s", run["levels"][-1]["dofs"], flush=True)
        return 0
    if argv and argv[0] == "refs":
        for p in sorted(OUT.glob("*.json")):
            run = json.loads(p.read_text())
            run["references"] = references(run)
            p.write_text(json.dumps(run, indent=1) + "\n")
            r = run["references"]
            print(p.stem, {k: (f"{v['value']:.6g} ± {v['allowance'] / abs(v['value']):.3%}" if isinstance(v, dict) else v)
                           for k, v in r.items()})
        return 0
    print(__doc__)
    return 2


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
