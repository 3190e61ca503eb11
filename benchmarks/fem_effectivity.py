"""Effectivity of the adaptive FEM's error estimates per goal, against converged references:

    python benchmarks/fem_effectivity.py run [--rtol R] [--before | --main] NAME ...  # runs → RUNS json
    python benchmarks/fem_effectivity.py table                                      # the markdown table
    python benchmarks/fem_effectivity.py replay NAME                               # a deep run's levels
    python benchmarks/fem_effectivity.py summary [NAME ...]                         # effectivity distributions

``run``: flexure.adaptive.analyze_adaptive on each design (names as benchmarks/fem_adaptive.py: the five
reference parts, or an unseen part of tests/data/fem_unseen) at ``rtol``; every level's goals, enriched
differences and estimates, the wall time and the 1-minute load go to RUNS (one entry per design, rtol
and mode; entries of mode "main 36a66ca" were made by that commit's code). ``--before``: the estimate as main 383f4e5 made it, 2 |J(u⁺) − J(u_h)| on every level (the
saturation ratio never measured, flexure.saturation), the same code otherwise; ``--main``: as main 36a66ca (q̂ measured, 2|d| where not).

``table``: each run's last level against the design's reference J∞ ± a (the deep nested run
tests/data/fem_reference/adaptive/NAME.json where it exists, else tests/data/fem_reference/levels.json):
effectivity e/E, E = |J − J∞|, with its range over the allowance, E ∈ [max(E − a, 0), E + a].

``replay``: the deep run's own levels, before (2|d|) and after (flexure.saturation) — the early levels
are judged fairly; the last ones are those the reference extrapolates from.

``summary``: every level of the deep runs (default: all of tests/data/fem_reference/adaptive) and the last
level of each RUNS entry, replayed under each estimate (``MODES``: 2|d| as main 383f4e5; q̂ measured, 2|d|
where not, the bridge from its own d, as main 36a66ca; no floor on the arms, as main 6e60bf3; now): the effectivity's min/median/max over the goals
whose reference resolves their error (allowance < half the true error), the count in [1, 3], and the
goals whose whole allowance range is below 1 or above 3.
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
RUNS = ROOT / "reports" / "fem_adaptive_effectivity.json"
GOALS = ("torsional_stiffness_Nm_per_rad", "gauge_strain_per_Nm")
KEEP = ("level", "dofs", "theta", "torsional_stiffness_Nm_per_rad", "gauge_strain_per_Nm", "gauge_strains",
        "enriched", "estimate", "kappa", "kappa_how", "goal_algebraic_error", "level_s", "peak_rss_gb",
        "q_unmeasured")


def references(name: str) -> dict:
    """{goal: (value, allowance, source)}: the deep nested run's where it has one (the same discrete problem as
    the adaptive runs: its load and fixed sets chosen on the same first mesh), else levels.json's (gmsh levels,
    the bands re-selected on each mesh: reentrant's stiffness limit is 0.3 % off the nested one)."""
    import fem_adaptive as fa

    out = {}
    levels = json.loads((fa.DATA / "levels.json").read_text())["references"].get(name, {})
    for k, v in levels.items():
        out[k] = (v["value"], v["allowance"], "levels.json")
    p = fa.OUT / f"{name}.json"
    if p.exists():
        for k, v in json.loads(p.read_text()).get("references", {}).items():
            if isinstance(v, dict) and math.isfinite(v["allowance"]):
                out[k] = (v["value"], v["allowance"], f"adaptive/{name}.json")
    return out


def goals_of(level: dict) -> dict:
    """{goal: (value, estimate)} of one level record."""
    est = level["estimate"]
    out = {g: (level[g], est[g]) for g in GOALS}
    for i, (v, e) in enumerate(zip(level["gauge_strains"], est["gauge_strains"])):
        out[f"gauge{i}"] = (v, e)
    return out


def effectivity(J: float, e: float, ref: tuple) -> dict:
    value, a = ref[0], ref[1]
    E = abs(J - value)
    lo, hi = max(E - a, 0.0), E + a
    return {"value": J, "estimate_rel": e / abs(J), "true_error_rel": E / abs(value), "allowance_rel": a / abs(value),
            "effectivity": e / E if E > 0 else math.inf,
            "effectivity_range": [e / hi if hi > 0 else math.inf, e / lo if lo > 0 else math.inf],
            "reference": ref[2] if len(ref) > 2 else ""}


def before_mode():
    """main's estimate, 2|d| on every level: the saturation ratio is never a measurement."""
    from flexure import saturation

    saturation.saturation_ratio = lambda *a, **k: (math.nan, "not measured (before: main 383f4e5)")
    saturation.Q_PRIOR = 0.0


#: mode → (saturation ratio measured, q where not measured, bridge not below its arms', the arms' floor)
MODES = {"2|d| (383f4e5)": (False, 0.0, False, False), "q̂, 2|d| unmeasured (36a66ca)": (True, 0.0, False, False),
         "no arm floor (6e60bf3)": (True, None, True, False), "now": (True, None, True, True)}


def replay_mode(levels: list[dict], mode: str, signs) -> list[dict]:
    """The levels' estimates recomputed from their J and d under one of ``MODES``."""
    from flexure import adaptive, saturation

    measured, q0, bridge, floor = MODES[mode]
    saved = saturation.saturation_ratio, saturation.Q_PRIOR, saturation.ARM_FLOOR
    saturation.ARM_FLOOR = saturation.ARM_FLOOR and floor
    if not measured:
        saturation.saturation_ratio = lambda *a, **k: (math.nan, "not measured")
    if q0 is not None:
        saturation.Q_PRIOR = q0
    try:
        out, prev, seen = [], None, {}
        for x in levels:
            if q0 is not None:           # the record's own unmeasured ratio is the current code's
                x = {**x, "q_unmeasured": q0}
            out.append({**x, **adaptive._enriched_estimates(x, prev, seen, signs if bridge else None)})
            prev = x
    finally:
        saturation.saturation_ratio, saturation.Q_PRIOR, saturation.ARM_FLOOR = saved
    return out


def arm_signs(name: str) -> list[float]:
    import fem_adaptive as fa
    from flexure.adaptive import ARM_SIGN
    from flexure.design import load_design

    return [ARM_SIGN.get(g.arm, 0.0) for g in load_design(fa.design_path(name)).gauges]


def summary(names: list[str], runs: list[dict]) -> str:
    import fem_adaptive as fa
    import numpy as np

    names = names or sorted(p.stem for p in fa.OUT.glob("*.json"))
    sources = [(n, json.loads((fa.OUT / f"{n}.json").read_text())["levels"], False) for n in names]
    sources += [(r["design"], r["levels"], True) for r in runs if r["mode"] != "before" and (not names or r["design"] in names)]
    rows = ["| estimate | goals judged | in [1, 3] | min / median / max | allowance range < 1 | > 3 |", "|---|---|---|---|---|---|"]
    for mode in MODES:
        eff, below, above = [], 0, 0
        for name, levels, last_only in sources:
            refs = references(name)
            done = replay_mode(levels, mode, arm_signs(name))
            for x in done[-1:] if last_only else done:
                for g, (J, e) in goals_of(x).items():
                    if g not in refs:
                        continue
                    ef = effectivity(J, e, refs[g])
                    lo, hi = ef["effectivity_range"]
                    below, above = below + (hi < 1), above + (lo > 3)
                    if ef["allowance_rel"] < 0.5 * ef["true_error_rel"]:
                        eff.append(ef["effectivity"])
        e = np.array(eff)
        rows.append(f"| {mode} | {len(e)} | {int(((e >= 1) & (e <= 3)).sum())} | {e.min():.2f} / {np.median(e):.2f} / "
                    f"{e.max():.2f} | {below} | {above} |")
    return "\n".join(rows)


def run(name: str, rtol: float, before: bool) -> dict:
    import fem_adaptive as fa
    from flexure.adaptive import analyze_adaptive
    from flexure.design import load_design

    t0 = time.perf_counter()
    res, _ = analyze_adaptive(load_design(fa.design_path(name)), rtol=rtol)
    wall = time.perf_counter() - t0
    lv = res["discretization_levels"]
    return {"design": name, "rtol": rtol, "mode": "before" if before else "after", "wall_s": wall,
            "load_1min": os.getloadavg()[0], "dofs": res["dofs"], "levels": [{k: x.get(k) for k in KEEP} for x in lv],
            "stopped_by": res["stopped_by"], "peak_rss_gb": max(x.get("peak_rss_gb") or 0 for x in lv)}


def replay(levels: list[dict], before: bool, signs=None) -> list[dict]:
    """The levels' estimates recomputed from their J and d (flexure.adaptive._enriched_estimates)."""
    return replay_mode(levels, "2|d| (383f4e5)" if before else "now", signs)


def _fmt(g: str, x: dict) -> str:
    lo, hi = x["effectivity_range"]
    ok = "" if 1 <= lo and hi <= 3 else (" **out**" if x["effectivity"] < 1 or x["effectivity"] > 3 else " (range)")
    return (f"{g} | {x['estimate_rel']:.3%} | {x['true_error_rel']:.3%} ± {x['allowance_rel']:.3%} | "
            f"{x['effectivity']:.2f} [{lo:.2f}, {hi:.2f}]{ok}")


def table(runs: list[dict]) -> str:
    rows = ["| part | rtol | mode | levels (DOFs) | wall s (load) | goal | estimate | true error ± a | effectivity [range] |",
            "|---|---|---|---|---|---|---|---|---|"]
    for r in runs:
        refs = references(r["design"])
        last = r["levels"][-1]
        dofs = ", ".join(f"{x['dofs'] / 1e3:.0f}k" for x in r["levels"])
        head = (f"| {r['design']} | {r['rtol']:g} | {r['mode']} | {len(r['levels'])} ({dofs}) | "
                f"{r['wall_s']:.0f} ({r['load_1min']:.1f}) | ")
        for g, (J, e) in goals_of(last).items():
            if g in refs:
                rows.append(head + _fmt(g, effectivity(J, e, refs[g])) + " |")
                head = "| | | | | | "
    return "\n".join(rows)


def main(argv: list[str]) -> int:
    if not argv:
        print(__doc__)
        return 2
    cmd, rest = argv[0], argv[1:]
    runs = json.loads(RUNS.read_text()) if RUNS.exists() else []
    runs = [r for r in runs if "mode" in r]          # this format only
    if cmd == "run":
        rtol, before, main36, names = 0.02, False, False, []
        it = iter(rest)
        for a in it:
            if a == "--rtol":
                rtol = float(next(it))
            elif a == "--before":
                before = True
            elif a == "--main":
                main36 = True
            else:
                names.append(a)
        if before:
            before_mode()
        if main36:                      # main 36a66ca's estimate: q̂ measured, 2|d| where not (the sizing sees it)
            from flexure import saturation

            saturation.Q_PRIOR = 0.0
        for name in names:
            r = run(name, rtol, before)
            if main36:
                r["mode"] = "main 36a66ca"
            runs = [x for x in runs if (x["design"], x["rtol"], x["mode"]) != (name, rtol, r["mode"])] + [r]
            RUNS.write_text(json.dumps(runs, indent=1) + "\n")
            print(f"{name} rtol {rtol:g} {r['mode']}: {r['wall_s']:.0f} s (load {r['load_1min']:.1f}), "
                  f"{[x['dofs'] for x in r['levels']]}, stopped by {r['stopped_by']}", flush=True)
        return 0
    if cmd == "table":
        runs.sort(key=lambda r: (r["design"], r["rtol"], r["mode"] != "before", r["mode"] == "after"))
        print(table(runs))
        return 0
    if cmd == "summary":
        print(summary(rest, runs))
        return 0
    if cmd == "replay":
        import fem_adaptive as fa

        deep = json.loads((fa.OUT / f"{rest[0]}.json").read_text())
        refs = references(rest[0])
        for before in (True, False):
            print("before (2|d|)" if before else "after (flexure.saturation)")
            for x in replay(deep["levels"], before, arm_signs(rest[0])):
                for g, (J, e) in goals_of(x).items():
                    if g in refs:
                        key = {GOALS[0]: "theta", GOALS[1]: "eps_ref"}.get(g, "g" + g[5:])
                        print(f"  L{x['level']} {x['dofs']:>8} {_fmt(g, effectivity(J, e, refs[g]))}  "
                              f"q̂ {x['kappa'].get(key, math.nan):.2f}")
        return 0
    print(__doc__)
    return 2


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
