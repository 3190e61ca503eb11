"""The saturation-aware goal estimate (flexure.saturation) on synthetic nested sequences: the
measured ratio q̂, the estimate's effectivity where its assumptions hold, and each failure mode."""

import math

import numpy as np
import pytest

from flexure import saturation as sat
from flexure.saturation import goal_estimate, saturation_ratio


def levels(J_exact: float, E0: float, r: float, q0: float, q1: float):
    """Two nested levels of a goal: P2 errors E0, r·E0; enriched errors q0·E0, q1·r·E0 → (J, d) each."""
    E1 = r * E0
    return (J_exact - E0, (1 - q0) * E0), (J_exact - E1, (1 - q1) * E1), E1


@pytest.mark.parametrize("q", [-0.3, 0.0, 0.2, 0.5, 0.6])
@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_constant_q_is_measured_exactly(q, sign):
    """Same q on both levels: q̂ = (J⁺_1 − J⁺_0)/(J_1 − J_0) = q, whatever the error's sign, and the
    estimate max(2, 1.5/(1 − q̂))|d| has the effectivity max(2(1 − q), 1.5)."""
    prev, cur, E1 = levels(3.0, sign * 1e-3, 0.5, q, q)
    qh, how = saturation_ratio(*prev, *cur, noise=1e-12)
    assert how == "measured" and qh == pytest.approx(q, abs=1e-9)
    e, q_used, _, measured = goal_estimate(*cur, prev, 1e-12)
    assert measured and q_used == pytest.approx(q, abs=1e-9)
    assert e / abs(E1) == pytest.approx(max(2 * (1 - q), 1.5), rel=1e-9)


def test_bracket_within_one_to_three_where_q_drifts_little():
    """q ∈ [−0.3, 0.6], changing by ≤ 0.1 between levels whose error falls by r ≤ 0.5: every
    effectivity in [1, 3] (the docstring's range, 1.0–2.6); the flat 2|d| misses at q = 0.6."""
    effs, flat = [], []
    for r in np.linspace(0.2, 0.5, 7):
        for q0 in np.linspace(-0.3, 0.6, 19):
            for dq in np.linspace(-0.1, 0.1, 5):
                q1 = q0 + dq
                if not -0.3 <= q1 <= 0.6:
                    continue
                prev, cur, E1 = levels(1.0, 2e-3, r, q0, q1)
                effs.append(goal_estimate(*cur, prev, 1e-12)[0] / E1)
                flat.append(2 * abs(cur[1]) / E1)
    assert 1.0 - 1e-9 <= min(effs) and max(effs) <= 2.6 + 1e-9
    assert min(flat) < 0.9                                       # the case the measurement is for


def test_first_level_takes_a_reentrant_edges_ratio():
    """No q̂ on a first level: q = Q_PRIOR = (2/3)^(4·½) = 4/9, e = 1.5/(1 − 4/9)|d| = 2.7|d|, not a measurement."""
    e, q, how, measured = goal_estimate(1.0, -3e-4, None, 0.0)
    assert sat.Q_PRIOR == pytest.approx(4 / 9) and q == sat.Q_PRIOR and not measured and "first level" in how
    assert e == pytest.approx(2.7 * 3e-4)


@pytest.mark.parametrize("q", [-0.11, 0.0, 0.12, 0.3, 0.45, 0.62])
def test_unmeasured_estimate_brackets_over_the_first_level_range(q):
    """The unmeasured factor 2.7 has the effectivity 2.7(1 − q) ∈ [1, 3] for q ∈ [−0.11, 0.63]: smooth
    parts (q 0.01–0.12) and re-entrant edges (q 0.3–0.62) alike; the flat 2|d| misses q > ½."""
    E = 1e-4
    e = goal_estimate(1.0 - E, (1 - q) * E, None, 0.0).e
    assert 1.0 <= e / E <= 3.0


@pytest.mark.parametrize("prev, cur, noise, why", [
    ((1.0 - 1e-3, 5e-4), (1.0 - 5e-4, -2e-4), 1e-12, "changed sign"),        # d crossed zero
    ((1.0 - 1e-3, 5e-4), (1.0 - 5e-4, 4e-4), 1e-12, "fell by less"),         # d barely fell: r near 1
    ((1.0 - 1e-3, 5e-4), (1.0 - 1e-3 + 1e-9, 2e-4), 1e-9, "algebraic"),      # the level change is noise
    ((1.0 - 1e-3, 5e-4), (1.0 - 1.2e-3, 2e-4), 1e-12, "q̂ ≥ 1"),               # J moved away while d fell
    ((1.0, 0.0), (1.0 - 1e-4, 2e-4), 1e-12, "changed sign"),                  # d = 0: no ratio
])
def test_no_measurement_falls_back(prev, cur, noise, why):
    """Where (2) is noise, q̂ is nan and the estimate takes Q_PRIOR (2.7|d|), or an earlier step's q̂."""
    q, how = saturation_ratio(*prev, *cur, noise)
    assert math.isnan(q) and why in how
    e, q_used, how, measured = goal_estimate(*cur, prev, noise)
    assert e == pytest.approx(2.7 * abs(cur[1])) and q_used == sat.Q_PRIOR and why in how and not measured
    e, q_used, how, measured = goal_estimate(*cur, prev, noise, q_prev=0.5)
    assert e == pytest.approx(3 * abs(cur[1])) and q_used == 0.5 and "earlier step" in how and not measured


def test_weak_saturation_is_capped_and_said():
    """q̂ above Q_MAX is used as Q_MAX (factor 1.5/(1 − Q_MAX) = 7.5) and the method says so."""
    prev, cur, E1 = levels(1.0, 1e-3, 0.3, 0.9, 0.9)
    e, q, how, measured = goal_estimate(*cur, prev, 1e-12)
    assert measured and q == pytest.approx(0.9) and f"used as {sat.Q_MAX:g}" in how
    assert e == pytest.approx(sat.SAFETY / (1 - sat.Q_MAX) * abs(cur[1]))
    assert e / E1 == pytest.approx(0.75)                               # a floor, not a bracket, there


def test_not_finite_is_not_a_measurement():
    assert math.isnan(saturation_ratio(1.0, math.nan, 1.0, 1e-4, 0.0)[0])


def test_an_arm_whose_difference_collapses_is_held_at_the_sets_floor():
    """Four arms with P2 errors of one size on a part with a sharp re-entrant edge (set q 0.45); on one the
    enriched error stays at the set's pollution size (|E⁺| ≈ q S, not q |E_i|), so its d is a twentieth of its
    error: (3) alone misses it (effectivity < 0.2); held at the set's q × the median of the arms' estimates it
    brackets, and the other arms are untouched. On a part without one (q_unmeasured Q_SMOOTH, measured q
    0.05) the floor is Q_SMOOTH × the median: an arm whose error is genuinely a quarter of the others' keeps
    its own estimate."""
    E = np.array([1.0e-3, -0.9e-3, 1.1e-3, 0.5e-3])
    d = np.array([0.8e-3, -0.7e-3, 0.9e-3, 0.025e-3])                 # arm 4: E⁺ = 0.475e-3 ≈ 0.45 S
    e = np.array([sat.saturation_estimate(x, 0.2) for x in d])
    assert e[3] / abs(E[3]) < 0.2
    held = sat.arm_floor(e, [0.45] * 4, sat.Q_PRIOR)
    assert 1.0 <= held[3] / abs(E[3]) <= 3.0
    np.testing.assert_array_equal(held[:3], e[:3])
    smooth = 2.0 * 0.95 * np.abs(E) * np.array([1.0, 1.0, 1.0, 0.5])     # 2|d|, q 0.05; arm 4's error 0.25e-3
    kept = sat.arm_floor(smooth, [0.05] * 4, sat.Q_SMOOTH)
    np.testing.assert_array_equal(kept, smooth)
    assert smooth[3] < 0.5 * np.median(smooth)                       # a floor of ½ would have lifted it
    assert sat.arm_floor(e[:1], [0.9])[0] == e[0] and sat.arm_floor([], []).size == 0
