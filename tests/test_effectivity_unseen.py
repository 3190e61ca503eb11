"""The adaptive estimate's effectivity on an unseen exact-geometry part (tests/data/fem_unseen/
three_spoke_thin.step) against its stored converged reference (tests/data/fem_reference/adaptive/
three_spoke_thin.json: a deep nested adaptive run to 701 k DOFs, benchmarks/fem_adaptive.py)."""

import json
from pathlib import Path

import pytest

DATA = Path(__file__).parent / "data"


@pytest.mark.slow
@pytest.mark.xfail(strict=True, reason=(
    "measured 2026-11-26 (benchmarks/fem_effectivity.py, load 6-8): the default run stops on its first "
    "level (35 k DOFs) with effectivities stiffness 1.40 [1.32, 1.48], bridge 1.03 [0.92, 1.15], arms 2.84 "
    "[2.03, 4.72], 1.58, 1.53, 0.75 [0.70, 0.80]: arm 4's enriched difference is 0.052 % against a true "
    "error of 0.139 ± 0.009 % (its saturation ratio q = 0.62 > 1/2), and a first level has no second one to "
    "measure q on (flexure.saturation)"))
def test_default_run_brackets_every_goal_within_3x_on_three_spoke_thin():
    """Every goal (stiffness, bridge strain, each arm) at the default --rtol: e/|J − J∞| in [1, 3]
    over the whole allowance of the reference, J∞ ± a."""
    from flexure.adaptive import analyze_adaptive
    from flexure.design import load_design

    res, _ = analyze_adaptive(load_design(DATA / "fem_unseen" / "three_spoke_thin.toml"))
    ref = json.loads((DATA / "fem_reference" / "adaptive" / "three_spoke_thin.json").read_text())["references"]
    last = res["discretization_levels"][-1]
    goals = {"torsional_stiffness_Nm_per_rad": (last["torsional_stiffness_Nm_per_rad"],
                                                last["estimate"]["torsional_stiffness_Nm_per_rad"]),
             "gauge_strain_per_Nm": (last["gauge_strain_per_Nm"], last["estimate"]["gauge_strain_per_Nm"]),
             **{f"gauge{i}": (v, e) for i, (v, e) in enumerate(zip(last["gauge_strains"],
                                                                 last["estimate"]["gauge_strains"]))}}
    bad = {}
    for goal, (J, e) in goals.items():
        E, a = abs(J - ref[goal]["value"]), ref[goal]["allowance"]
        lo, hi = e / (E + a), (e / (E - a) if E > a else float("inf"))
        if not (lo >= 1.0 and hi <= 3.0):
            bad[goal] = (round(lo, 2), round(hi, 2))
    assert not bad, bad
