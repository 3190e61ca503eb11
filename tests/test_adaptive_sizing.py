"""Sizing of the adaptive levels (flexure.adaptive_sizing): the step, the memory budget, the marks."""

import json
import subprocess
import sys

import numpy as np
import pytest

from flexure import adaptive_sizing as sz


def test_rates_read_the_raw_differences_not_the_factor_change():
    """A goal whose enriched difference |d| fell at rate 1 while its estimate's factor rose from 2 to
    2.6 (q̂ measured on the second level): the rate is |d|'s, not the estimate's slower one."""
    prev = {"dofs": 100_000, "rel": [0.04], "raw": [0.02]}
    cur = {"dofs": 200_000, "rel": [0.026], "raw": [0.01]}
    assert sz.rates(prev, cur)[0] == pytest.approx(1.0)
    assert sz.rates({k: v for k, v in prev.items() if k != "raw"}, cur)[0] == pytest.approx(np.log(0.04 / 0.026) / np.log(2))
    assert sz.rates(None, cur)[0] == sz.RATE_PRIOR
    rose = {"dofs": 100_000, "rel": [0.035, 0.01]}                  # the first goal's estimate rose: no rate
    r = sz.rates({"dofs": 50_000, "rel": [0.019, 0.04]}, rose)
    assert r[0] == sz.RATE_PRIOR and r[1] == sz.RATE_MAX


def test_target_reaches_rtol_at_the_rate_and_the_first_step_allows_for_the_factor_rise():
    n = 50_000
    want = sz.target_dofs(n, [0.04, 0.01], np.array([1.0, 1.0]), 0.02, 1.3)
    assert want == pytest.approx(2 * n, abs=1)                   # (0.04/0.02)^(1/1)
    first = sz.target_dofs(n, [0.04, 0.01], np.array([1.0, 1.0]), 0.02, 1.3, rise=sz.FACTOR_RISE_MEAN)
    assert first == pytest.approx(2 * sz.FACTOR_RISE_MEAN * n, abs=1)
    assert 1.0 < sz.FACTOR_RISE_MEAN < 1.5                            # within the factor's range [2, 3] / 2
    assert sz.target_dofs(n, [0.001], np.array([1.0]), 0.02, 1.3) == int(1.3 * n)
    assert sz.target_dofs(n, [10.0], np.array([1.0]), 0.02, 1.3) == int(sz.MAX_GROWTH * n)


def test_next_dofs_never_leaves_a_level_stranded_below_the_cap():
    g = 1.3
    assert sz.next_dofs(100, 200, 1000, g) == 200                    # room for another step after it
    assert sz.next_dofs(100, 900, 1000, g) == 1000                   # the last step: to the cap
    m = sz.next_dofs(100, 900, 1000, g, prior=True)                  # ... not on the a-priori rate alone:
    assert g * 100 <= m < 1000 / g                                    # a measurable step, room for the last
    assert sz.next_dofs(100, 900, 1000, g, split=False, prior=True) == 1000
    assert sz.next_dofs(100, 200, 1000, g, prior=True) == 200         # room after it: as asked
    m = sz.next_dofs(100, 600, 500, g)                               # rtol out of reach: one step
    assert m == int(min(max(np.sqrt(100 * 500), 500 / (sz.LANDING * g ** 2)), 500 / (sz.LANDING * g)))
    assert 130 <= m and sz.LANDING * m * g <= 500                    # ... leaving room for the last one
    assert sz.next_dofs(m, 5000, 500, g, split=False) == 500         # ... which goes to the cap
    assert sz.next_dofs(300, 5000, 500, g) == 500                    # no room for two: straight to the cap
    assert sz.next_dofs(100, 5000, 150, g) == 150                    # only one measurable step left
    assert sz.next_dofs(100, 5000, 120, g) == 0                      # none: the budget stops the run
    for want in (140, 300, 800, 1000, 3000):                          # never above the cap, never a step
        nxt = sz.next_dofs(100, want, 1000, g)                        # too small to measure
        assert 130 <= nxt <= 1000


def test_a_target_beyond_the_cap_only_at_a_slow_measured_rate_steps_to_the_cap():
    """Beyond the cap at the measured rate (0.67: 359 k DOFs at ± 2 % want 1.19 M for 1 %) but not at the
    a-priori rate (718 k): the cap, not the split; beyond it at both, the split as before; never the first step."""
    g, n, cap = 1.33, 359_000, 844_000
    rel, rate = [0.02, 0.004], np.array([0.67, 0.5])
    want, hope = sz.target_dofs(n, rel, rate, 0.01, g), sz.hopeful_target(n, rel, rate, 0.01, g)
    assert want > cap >= hope == pytest.approx(2 * n, abs=1)
    assert sz.next_dofs(n, want, cap, g, hope=hope) == cap
    split = sz.next_dofs(n, want, cap, g)
    assert g * n <= split < cap and sz.next_dofs(n, want, cap, g, hope=int(1.2 * cap)) == split
    assert sz.next_dofs(100, 900, 1000, g, prior=True, hope=900) < 1000      # the first step: split as before
    assert sz.hopeful_target(n, rel, np.array([1.2, 1.2]), 0.01, g) == sz.target_dofs(n, rel, np.array([1.2, 1.2]), 0.01, g)


def test_memory_model_is_linear_with_its_margin_and_keeps_the_last_measured_level():
    per = sz.peak_per_dof(100_000, 0.3, 0.9)
    assert per == pytest.approx(6e-6)
    assert sz.peak_per_dof(200_000, 0.3, 1.0, per, measured=False) == per   # a sampled peak: not below the last
    assert sz.peak_per_dof(200_000, 0.3, 1.0, per) == pytest.approx(3.5e-6)  # a measured one: its own
    cap = sz.memory_dofs(0.3, per, 3.0)
    assert sz.predicted_peak_gb(cap, 0.3, per) == pytest.approx(3.0, rel=1e-4)
    assert sz.predicted_peak_gb(cap, 0.3, per) - 0.3 == pytest.approx(sz.MEMORY_MARGIN * per * cap)


_RUN = """
import json, resource, sys
from flexure.design import load_design
from flexure.adaptive import analyze_adaptive
res, _ = analyze_adaptive(load_design(sys.argv[1]), rtol=float(sys.argv[2]), max_memory_gb=float(sys.argv[3]))
lv = res["discretization_levels"]
print(json.dumps({"stopped": res["stopped_by"], "peak_gb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e6,
                  "levels": [{k: l.get(k) for k in ("dofs", "peak_rss_gb", "predicted_peak_gb", "sizing")} for l in lv]}))
"""


def _run(rtol, budget_gb):
    out = subprocess.run([sys.executable, "-c", _RUN, "designs/paper_disc.toml", str(rtol), str(budget_gb)],
                         capture_output=True, text=True, check=True, timeout=900)
    return json.loads(out.stdout.strip().splitlines()[-1])


@pytest.mark.slow
@pytest.mark.xfail(strict=False, reason=(
    "measured 2026-11-26: the same level's peak varies between runs more than MEMORY_MARGIN 1.2 covers. "
    "Quiet, main venv: level 1 (73.7 k DOFs) 0.67, 0.75, 0.75, 0.79 GB in four runs; CI (.ci/run, fresh venv, "
    "-n 2 under load): level 1 at 94.6 k DOFs 0.986 GB against its predicted 0.875 (1.13x); the same venv "
    "afterwards, alone: 0.87 against 0.99. The per-level prediction is not a guarantee until the spread's "
    "source (allocator reuse, numba compiling or threads inside a level) is found"))
def test_a_tight_memory_budget_holds_and_each_level_stays_under_its_prediction():
    """The paper disc at --rtol 0.002 (unreachable) under a budget just above its first level's peak,
    in a fresh process (ru_maxrss is the process's): every level's measured peak is below the peak its
    predecessor predicted for it, the run stops by the memory budget, and the process's peak, the final
    six-case figures included, stays within the budget (RSS is exact to a page; 2 % for the allocator's
    unreturned pages)."""
    free = _run(0.02, 100.0)
    first = free["levels"][0]["peak_rss_gb"]
    budget = first + 0.35
    res = _run(0.002, budget)
    assert res["stopped"] == "memory"
    assert len(res["levels"]) >= 2
    for lv in res["levels"][1:]:
        assert lv["peak_rss_gb"] <= lv["predicted_peak_gb"] * 1.02, lv
    assert res["peak_gb"] <= budget * 1.02, (res["peak_gb"], budget)


def test_raw_relative_removes_each_goals_own_factor():
    """Estimates 2|d| (stiffness) and 2.6|d| (the arms, q̂ measured): the raw shares are rel/2, rel/2.6."""
    rec = {"theta": 2e-3, "torsional_stiffness_Nm_per_rad": 500.0,
           "estimate": {"torsional_stiffness_Nm_per_rad": 500.0 * 0.04, "gauge_strains": [2.6e-7, 5.2e-7]}}
    d = {"theta": -0.02 * 2e-3, "gauges": [1e-7, -2e-7]}
    rel = {"torsional_stiffness_Nm_per_rad": 0.04, "arms": [0.01, 0.02]}
    assert sz.raw_relative(rec, rel, d) == pytest.approx([0.02, 0.01 / 2.6, 0.02 / 2.6])
    assert sz.raw_relative(rec, rel, None) == [0.04, 0.01, 0.02]


def test_marks_hit_the_target_and_never_exceed_the_limit():
    """Topology-only trials on a box mesh: the marks give about the target's DOFs (the bisection with
    them gives exactly the predicted count), and a limit below the target is not exceeded."""
    from flexure.mesh import box_mesh, to_quadratic
    from flexure.refine import TaggedMesh, bisect

    tm = TaggedMesh.untagged(to_quadratic(box_mesh(6, 6, 6)))
    comb = np.random.default_rng(0).random(tm.mesh.n_elements)
    n0 = tm.mesh.n_dofs
    marked, info = sz.marks_for(tm, comb, int(1.8 * n0), rounds=2)
    assert bisect(tm, marked, rounds=2)[0].mesh.n_dofs == info["predicted_dofs"]
    assert abs(info["predicted_dofs"] - 1.8 * n0) <= 0.1 * 1.8 * n0
    assert info["gain"] > 0
    again, info2 = sz.marks_for(tm, comb, int(1.8 * n0), rounds=2, gain=info["gain"])
    assert len(info2["trials"]) == 2                               # one trial from the measured gain
    _, capped = sz.marks_for(tm, comb, int(1.8 * n0), rounds=2, limit=int(1.4 * n0))
    assert n0 < capped["predicted_dofs"] <= 1.4 * n0


def test_time_cap_is_what_is_left_over_the_last_levels_seconds_per_dof_with_its_margin():
    per = sz.seconds_per_dof(400_000, 16.0)                     # 40 µs a DOF
    assert per == pytest.approx(4e-5)
    assert sz.time_dofs(30.0, per) == int(30.0 / (sz.TIME_MARGIN * 4e-5))
    assert sz.time_dofs(-5.0, per) == 0                          # past the budget: no next level
    # as a cap of next_dofs: a target beyond it steps to it where no measurable step fits after it
    cap = sz.time_dofs(30.0, per)
    assert sz.next_dofs(400_000, 2_000_000, cap, 1.33, split=False) == cap
    assert sz.next_dofs(400_000, 2_000_000, sz.time_dofs(5.0, per), 1.33) == 0


def test_a_time_cap_is_spent_by_the_steps():
    """The time budget is used up by each level (``spent``): a target leaving no time for a measurable step
    after it goes to the cap at once, and no intermediate step is made that would spend the last level's time."""
    g = 1.33
    assert sz.next_dofs(84_000, 500_000, 850_000, g) == 500_000                       # memory cap: room after it
    assert sz.next_dofs(84_000, 500_000, 850_000, g, spent=5_000_000) == 500_000      # time ample: the same
    assert sz.next_dofs(84_000, 500_000, 850_000, g, spent=969_000) == 850_000        # 469 k left: the last step
    assert sz.next_dofs(300_000, 2_000_000, 850_000, g, split=True) == 504_975         # memory cap: split
    assert sz.next_dofs(300_000, 2_000_000, 850_000, g, split=True, spent=5_000_000) == 504_975
    assert sz.next_dofs(300_000, 2_000_000, 850_000, g, split=True, spent=1_200_000) == 850_000

