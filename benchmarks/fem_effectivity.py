"""Effectivity of the adaptive FEM's error estimates, and its wall time, at a stated --rtol:

    python benchmarks/fem_effectivity.py [--rtol R] [--out FILE.json] NAME [NAME ...]

For each design (names as benchmarks/fem_adaptive.py: the five reference parts, or an unseen part of
tests/data/fem_unseen) run flexure.adaptive.analyze_adaptive at ``rtol`` and compare every goal's
estimate e with its true error E = |J − J∞| against a converged reference J∞ ± a:

* the reference parts: tests/data/fem_reference/levels.json (fine gmsh levels + extrapolation;
  bridge strain and stiffness);
* the unseen parts: the deep adaptive run of benchmarks/fem_adaptive.py (tests/data/fem_reference/
  adaptive/NAME.json; bridge strain, stiffness and each gauge).

effectivity = e / E, with its range over the reference's allowance, E ∈ [max(|J − J∞| − a, 0), |J − J∞| + a].
An estimate brackets its error when e ≥ E. Wall times are of a shared machine: state its load.
"""

from __future__ import annotations

import json
import math
import os
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))


def _references(name: str) -> dict:
    """{goal: (value, allowance)} of a design's converged reference."""
    import fem_adaptive as fa

    levels = json.loads((fa.DATA / "levels.json").read_text())["references"]
    if name in levels:
        return {k: (v["value"], v["allowance"]) for k, v in levels[name].items()}
    deep = json.loads((fa.OUT / f"{name}.json").read_text())["references"]
    return {k: (v["value"], v["allowance"]) for k, v in deep.items() if isinstance(v, dict)}


def _goals(res: dict) -> dict:
    """{goal: (value, estimate)} of an adaptive result (the last level's goal values)."""
    last = res["discretization_levels"][-1]
    est = last["estimate"]
    out = {"torsional_stiffness_Nm_per_rad": (last["torsional_stiffness_Nm_per_rad"], est["torsional_stiffness_Nm_per_rad"]),
           "gauge_strain_per_Nm": (last["gauge_strain_per_Nm"], est["gauge_strain_per_Nm"])}
    for i, (v, e) in enumerate(zip(last["gauge_strains"], est["gauge_strains"])):
        out[f"gauge{i}"] = (v, e)
    return out


def measure(name: str, rtol: float) -> dict:
    import fem_adaptive as fa
    from flexure.adaptive import analyze_adaptive
    from flexure.design import load_design

    t0 = time.perf_counter()
    res, _ = analyze_adaptive(load_design(fa.design_path(name)), rtol=rtol)
    wall = time.perf_counter() - t0
    refs = _references(name)
    rows = {}
    for goal, (J, e) in _goals(res).items():
        if goal not in refs:
            continue
        ref, a = refs[goal]
        E = abs(J - ref)
        lo, hi = max(E - a, 0.0), E + a
        rows[goal] = {"value": J, "estimate_rel": e / abs(J), "true_error_rel": E / abs(ref),
                      "allowance_rel": a / abs(ref), "effectivity": e / E if E > 0 else math.inf,
                      "effectivity_range": [e / hi if hi > 0 else math.inf, e / lo if lo > 0 else math.inf],
                      "brackets": e >= E}
    return {"design": name, "rtol": rtol, "wall_s": wall, "load_1min": os.getloadavg()[0],
            "dofs": res["dofs"], "levels": len(res["discretization_levels"]), "stopped_by": res["stopped_by"],
            "peak_rss_gb": max(x.get("peak_rss_gb") or 0 for x in res["discretization_levels"]), "goals": rows}


def main(argv: list[str]) -> int:
    rtol, out, names = 0.02, None, []
    it = iter(argv)
    for a in it:
        if a == "--rtol":
            rtol = float(next(it))
        elif a == "--out":
            out = Path(next(it))
        else:
            names.append(a)
    if not names:
        print(__doc__)
        return 2
    runs = []
    for name in names:
        r = measure(name, rtol)
        runs.append(r)
        print(f"{name}: {r['wall_s']:.0f} s wall (load {r['load_1min']:.1f}), {r['dofs']} dofs, {r['levels']} levels, "
              f"stopped by {r['stopped_by']}, peak {r['peak_rss_gb']:.2f} GB", flush=True)
        for g, x in r["goals"].items():
            print(f"  {g:32s} est {x['estimate_rel']:.3%}  true {x['true_error_rel']:.3%} ± {x['allowance_rel']:.3%}  "
                  f"eff {x['effectivity']:.2f} [{x['effectivity_range'][0]:.2f}, {x['effectivity_range'][1]:.2f}]"
                  f"{'' if x['brackets'] else '  UNDER'}", flush=True)
        if out is not None:
            out.write_text(json.dumps(runs, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
