"""The ``--rtol`` refinement's level choice (flexure.convergence.next_level, analyze_with_error) on
a synthetic analysis: Q(f) = Q∞ (1 + c f) (order 1, like a stiffness at a singular edge) and
DOFs n(f) = n₁ f^−2, so every number below follows from the formulas, not from a mesh."""

import math

import pytest

import flexure.analysis as A
from flexure.convergence import FILL, MIN_LAST_RATIO, analyze_with_error, next_level

N1, C, Q_INF = 100_000, 0.05, 3000.0


def _levels(factors):
    return [{"h_factor": f, "dofs": int(N1 * f ** -2)} for f in factors]


def test_next_level_is_h_over_root2_while_it_fits():
    f, predicted, last = next_level(_levels([2 ** 0.5, 1.0, 2 ** -0.5]), max_dofs=10 ** 7)
    assert f == pytest.approx(0.5) and not last
    assert predicted == pytest.approx(N1 * 4, rel=1e-4)          # the fitted exponent is 2, not 3


def test_next_level_fills_the_dof_budget_then_stops():
    levels = _levels([2 ** 0.5, 1.0, 2 ** -0.5])                 # finest: 200k dofs
    f, predicted, last = next_level(levels, max_dofs=350_000)    # h/√2 would be 400k
    assert last and predicted == int(FILL * 350_000)
    assert N1 * f ** -2 == pytest.approx(FILL * 350_000, rel=1e-4)
    assert 2 ** -0.5 / f >= MIN_LAST_RATIO
    f, predicted, last = next_level(levels, max_dofs=230_000)    # room for only 1.04× finer h
    assert f is None and predicted > 230_000


def _fake_analyze(design, size=None, order=None, progress=False, h_factor=1.0, max_elements=None):
    q = Q_INF * (1 + C * h_factor)
    res = {"dofs": int(N1 * h_factor ** -2), "total_s": 0.0, "order": 2, "warnings": [],
           "mesh": {"h_gauge_m": 1e-4 * h_factor}, "gauge_arm_imbalance": 0.0,
           "gauge_strain_per_Nm": 1e-5, "sensitivity_mV_per_V_per_Nm": 0.02,
           "torsional_stiffness_Nm_per_rad": q, "safety_factor": 4.0}
    return res, None


class _Gauge:
    length_m = width_m = 1e-3


class _Design:
    gauges = [_Gauge()] * 4


@pytest.mark.parametrize("max_dofs, reached", [(10 ** 7, True), (700_000, True), (500_000, False)])
def test_rtol_uses_the_budget_and_says_when_it_is_not_enough(monkeypatch, max_dofs, reached):
    """rtol 0.03 on an order-1 figure whose GCI estimate is 1.25 c f: reached at f ≤ 0.48, i.e.
    435k dofs. Unlimited: h/√2 steps to f = 0.354. Cap 700k: h/√2 (400k at f = 0.5, estimate
    3.1 %), then one level fitted under the cap (630k, f = 0.398, 2.5 %). Cap 500k: the fitted
    level (450k, f = 0.471) is only 1.06× finer than f = 0.5: no level, a warning."""
    monkeypatch.setattr(A, "analyze", _fake_analyze)
    res, _ = analyze_with_error(_Design(), rtol=0.03, max_dofs=max_dofs)
    dofs = [lv["dofs"] for lv in res["discretization_levels"]]
    assert max(dofs) <= max_dofs
    est = res["torsional_stiffness_Nm_per_rad_error_estimate"] / res["torsional_stiffness_Nm_per_rad"]
    f = res["discretization_levels"][-1]["h_factor"]
    assert est == pytest.approx(1.25 * C * f * Q_INF / res["torsional_stiffness_Nm_per_rad"], rel=1e-6)
    assert (est <= 0.03) == reached
    warned = [w for w in res["warnings"] if "--rtol 0.03 not reached" in w]
    assert bool(warned) != reached
    if max_dofs == 700_000:
        assert dofs[-1] == pytest.approx(FILL * max_dofs, rel=1e-3) and math.isclose(f, (N1 / dofs[-1]) ** 0.5,
                                                                                         rel_tol=1e-3)
