"""Build tests/data/fem_reference/levels.json: the project's mesh levels on the five reference
geometries and the references its discretization-error estimate is checked against
(tests/test_fem_reference.py).

    python benchmarks/fem_levels.py              # compute every level (about 15 min on 2 cores)
    python benchmarks/fem_levels.py --from DIR   # reuse DIR/NAME.jsonl (fem_reference.py --project
                                                 # DESIGN with the FINE factors, one line per level)

Levels: h × 2^(−k/4), k = −2 … 5 (√2 … 0.42, ``fine``); the default levels of
flexure.convergence (√2, 1, 1/√2) are among them (``levels``).

Reference. Where a figure Q still moves at the finest level, that level is not the limit. Every
singularity of these parts (sharp re-entrant edges, the edges of the supports) has an exponent
λ ≥ 1/2, so no figure converges slower than h^(2λ) = h once the levels are in the asymptotic
range; the limit then lies between the finest level Q_f and the order-1 extrapolation Q_1
(least squares Q = Q_1 + C·h over the four finest levels). The reference is the middle of
[Q_f, Q_1]; its allowance is half that interval plus the rms residual of the fit (the scatter of
non-nested meshes from level to level). The answer's true error is then |Q_answer − reference|
within ± allowance: the estimate brackets it when estimate ≥ true error − allowance, and is at most
3× conservative when estimate ≤ 3 (true error + allowance) (``ratio_checked``; ``misses`` lists the
rest with the measured ratio).
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / "tests" / "data" / "fem_reference"
DESIGNS = {"paper_disc": ROOT / "designs" / "paper_disc.toml", "reentrant": DATA / "reentrant.toml",
           "step_part": DATA / "step_part.toml", "thick_disc": DATA / "thick_disc.toml",
           "thick_disc_stl": DATA / "thick_disc_stl.toml"}
FINE = tuple(2.0 ** (-k / 4) for k in range(-2, 6))
FIGURES = ("gauge_strain_per_Nm", "torsional_stiffness_Nm_per_rad")
FIT_LEVELS = 4


def reference(levels: list[dict], figure: str) -> dict:
    """Middle of [finest level, order-1 extrapolation of the FIT_LEVELS finest], ± half + rms."""
    h = np.array([lv["h_factor"] for lv in levels[-FIT_LEVELS:]])
    q = np.array([lv[figure] for lv in levels[-FIT_LEVELS:]])
    A = np.column_stack([np.ones_like(h), h])
    coef = np.linalg.lstsq(A, q, rcond=None)[0]
    rms = float(np.sqrt(((q - A @ coef) ** 2).sum() / (len(q) - 2)))
    q_f, q_1 = float(q[-1]), float(coef[0])
    return {"value": 0.5 * (q_f + q_1), "allowance": 0.5 * abs(q_1 - q_f) + rms,
            "how": (f"between the finest level {q_f:.6g} (h x {h[-1]:.3g}, {levels[-1]['dofs']:,} dofs) and the "
                    f"order-1 extrapolation {q_1:.6g} of the levels h x {', '.join(f'{x:.3g}' for x in h)}; "
                    f"allowance: half the interval + the fit's rms residual {rms:.3g}")}


def build(fine: dict[str, list[dict]]) -> dict:
    from flexure.convergence import FACTORS, estimate_from_levels

    levels = {n: [lv for lv in fl if any(abs(lv["h_factor"] - f) < 1e-9 for f in FACTORS)]
              for n, fl in fine.items()}
    refs, misses = {}, {}
    for name, fl in fine.items():
        refs[name] = {}
        for figure in FIGURES:
            ref = reference(fl, figure)
            e = estimate_from_levels(levels[name], figure, 2)[0]
            true = abs(levels[name][-1][figure] - ref["value"])
            ratio = e / (true + ref["allowance"])
            ref.update(estimate_over_far_end=ratio, ratio_checked=bool(ratio <= 3.0),
                       brackets=bool(e >= true - ref["allowance"]))
            refs[name][figure] = ref
            if ratio > 3.0 or not ref["brackets"]:
                v = ref["value"]
                misses[f"{name}/{figure}"] = (f"estimate {e / v:.3%}; true error {true / v:.3%} ± {ref['allowance'] / v:.3%}: "
                                              f"{ratio:.3g} x its far end" + ("" if ref["brackets"] else ", NOT bracketed"))
    return {"about": "benchmarks/fem_levels.py (how the references are made) and tests/test_fem_reference.py",
            "levels": levels, "references": refs, "misses": misses, "fine": fine}


def main(argv: list[str]) -> int:
    sys.path[:0] = [str(ROOT), str(ROOT / "benchmarks")]
    from fem_reference import project_level

    from flexure.design import load_design

    src = Path(argv[argv.index("--from") + 1]) if "--from" in argv else None
    fine = {}
    for name, path in DESIGNS.items():
        if src is not None:
            fine[name] = [json.loads(line) for line in (src / f"{name}.jsonl").read_text().splitlines() if line]
        else:
            fine[name] = [project_level(load_design(path), f) for f in FINE]
        got = [lv["h_factor"] for lv in fine[name]]
        if not np.allclose(got, FINE, rtol=0, atol=1e-12):
            raise SystemExit(f"{name}: levels {got}, expected {list(FINE)}")
    out = build(fine)
    (DATA / "levels.json").write_text(json.dumps(out, indent=1) + "\n")
    for k, v in out["misses"].items():
        print(f"miss {k}: {v}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
