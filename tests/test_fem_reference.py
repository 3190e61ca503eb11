"""The FEM answer and its discretization-error estimate against independent references, on five
geometries: the paper disc, the thick disc (5 mm, no fillets, 0.5 mm gauges), the same disc as an
STL, a STEP part and a re-entrant part (all but the paper disc in tests/data/fem_reference/).

References: scikit-fem P2 (its own assembly, boundary conditions and solve; only the gmsh mesh and
the node selections are shared) on the design's mesh with every size × 0.5 (the paper disc also
× 0.354, 309k DOFs), about 2–4× the answer level's DOFs (benchmarks/fem_reference.py). On the
same mesh scikit-fem and the project agree to 2e-7 (paper disc, h × 0.5, 138,132 DOFs: 5.757121e-5
vs 5.757122e-5 per N·m, 1755.805 vs 1755.805 N·m/rad), so the difference to a finer reference is
discretization error, not a different model; the thick disc's and the STL's references are the
project's own P2 at h × 0.5 for that reason (scikit-fem took 7–13 min per reference on the
loaded machine). A reference is not exact: its own error allowance and how it was set are stored
beside it (levels.json, ``references``); where a stiffness is still falling, the distance to the
reference is a lower bound of the true error (allowance 0).

The project's levels (h × 2**0.5, 1, 2**-0.5, what ``analyze_with_error`` computes by default)
are stored in levels.json (``python benchmarks/fem_reference.py --project DESIGN
1.4142135623730951 1 0.7071067811865476``): the paper disc and thick discs take minutes per run,
too long to recompute in a test. The estimate is taken from them by the shipped code
(``flexure.convergence.usable_levels`` + ``richardson``); one test recomputes a stored level and one
test runs the whole default path on the STEP part.
"""

import json
import math
from pathlib import Path

import pytest

from flexure.convergence import FIGURES, analyze_with_error, richardson, usable_levels
from flexure.design import load_design

DATA = Path(__file__).resolve().parent / "data" / "fem_reference"
STORED = json.loads((DATA / "levels.json").read_text())


def estimate_from_levels(levels: list[dict], figure: str) -> float:
    used, _ = usable_levels(levels)
    e, _, _ = richardson([lv["h_factor"] for lv in used], [lv["dofs"] for lv in used],
                         [lv[figure] for lv in used], FIGURES[figure](2))
    return e


def cases():
    for name, refs in sorted(STORED["references"].items()):
        for figure in refs:
            yield name, figure


@pytest.mark.parametrize("name,figure", list(cases()))
def test_error_estimate_brackets_the_true_error_at_most_3x(name, figure):
    """estimate ≥ true error and, where the target is met (``ratio_checked``), ≤ 3 × the true error,
    each allowing for the reference's own error. Where it is not met the reference says why, and
    levels.json lists what is not bracketed (``misses``: left out here, reported)."""
    levels = STORED["levels"][name]
    ref = STORED["references"][name][figure]
    value = levels[-1][figure]
    true_error = abs(value - ref["value"])
    estimate = estimate_from_levels(levels, figure)
    assert math.isfinite(estimate)
    assert estimate >= true_error - ref["allowance"], (name, figure, true_error, estimate)
    if ref["ratio_checked"]:
        assert estimate <= 3.0 * (true_error + ref["allowance"]), (name, figure, true_error, estimate)


@pytest.mark.parametrize("name", sorted(STORED["references"]))
def test_default_answer_within_2_percent_of_the_reference(name):
    levels = STORED["levels"][name]
    ref = STORED["references"][name]["gauge_strain_per_Nm"]
    assert abs(levels[-1]["gauge_strain_per_Nm"] - ref["value"]) + ref["allowance"] <= 0.02 * ref["value"]


def test_levels_are_what_the_code_computes():
    """The stored levels are today's: the STEP part's coarsest level recomputed (the others share
    the code path) equals the stored one."""
    import importlib.util

    spec = importlib.util.spec_from_file_location("_fem_reference", DATA.parents[2] / "benchmarks" / "fem_reference.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    stored = STORED["levels"]["step_part"][0]
    now = mod.project_level(load_design(DATA / "step_part.toml"), stored["h_factor"])
    for key in ("dofs", "gauge_strain_per_Nm", "torsional_stiffness_Nm_per_rad"):
        assert now[key] == pytest.approx(stored[key], rel=1e-6), key


def test_default_path_on_the_step_part():
    """The whole default path (three levels, the estimate beside every figure): the stored levels,
    an estimate that brackets the reference, no slivers, arms within 2 %, no warnings."""
    res, _ = analyze_with_error(load_design(DATA / "step_part.toml"))
    stored = STORED["levels"]["step_part"]
    assert [lv["dofs"] for lv in res["discretization_levels"]] == [lv["dofs"] for lv in stored]
    ref = STORED["references"]["step_part"]["gauge_strain_per_Nm"]
    true_error = abs(res["gauge_strain_per_Nm"] - ref["value"])
    assert res["gauge_strain_per_Nm_error_estimate"] >= true_error - ref["allowance"]
    assert abs(res["gauge_strain_per_Nm"] - ref["value"]) <= 0.02 * ref["value"]
    assert res["mesh"]["n_slivers"] == 0 and res["mesh"]["min_dihedral_deg"] > 10.0
    assert res["gauge_arm_imbalance"] < 0.02 and res["warnings"] == []


@pytest.mark.parametrize("name", sorted(STORED["levels"]))
def test_arms_agree_within_2_percent_at_the_default_answer(name):
    """The four arms of these four-fold symmetric parts read the same |strain| within 2 % at the
    answer level (h × 1/√2), the STL disc included (1.34 %; 2.57 % at h × 1, 2.51 % at h × √2:
    tests/test_fem_thick_disc.py)."""
    assert STORED["levels"][name][-1]["gauge_arm_imbalance"] < 0.02
