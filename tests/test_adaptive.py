"""The adaptive, goal-oriented analysis (flexure.adaptive): its stopping rules, the two-level
calibration of the estimate, and the output contract, on a small annulus STL (fast)."""

import math

import pytest

from flexure import adaptive
from flexure.adaptive import analyze_adaptive, calibrate
from flexure.design import load_design

ANNULUS = """\
name = "annulus"
[geometry]
kind = "stl"
file = "annulus.stl"
[gauges]
grid_length_mm = 2.0
grid_width_mm = 2.0
{gauges}
[loads]
rated_torque_Nm = 2.0
load_radius_max_mm = 3.02
fixed_radius_min_mm = 9.9
[mesh]
size = "coarse"
order = 2
"""


def annulus(tmp_path, sections: int = 48):
    """A 3 mm thick annulus (r 3 … 10 mm) as an STL, four ±45° gauges at r = 6.5 mm on top."""
    import trimesh

    tm = trimesh.creation.annulus(r_min=3.0, r_max=10.0, height=3.0, sections=sections)    # mm
    tm.apply_translation((0, 0, 1.5))
    tm.export(tmp_path / "annulus.stl")
    gauges = []
    for arm, ang in zip((1, 2, 3, 4), (0.0, 90.0, 180.0, 270.0)):
        a = math.radians(ang)
        c = (6.5 * math.cos(a), 6.5 * math.sin(a), 3.0)
        ax = (math.cos(a + math.pi / 4), math.sin(a + math.pi / 4), 0.0) if arm % 2 else \
            (math.cos(a - math.pi / 4), math.sin(a - math.pi / 4), 0.0)
        gauges.append(f"[[gauges.gauge]]\ncentre_mm = [{c[0]:.6f}, {c[1]:.6f}, {c[2]:.6f}]\n"
                      f"axis = [{ax[0]:.9f}, {ax[1]:.9f}, 0.0]\narm = {arm}")
    (tmp_path / "annulus.toml").write_text(ANNULUS.format(gauges="\n".join(gauges)))
    return load_design(tmp_path / "annulus.toml")


def test_calibration_rules():
    """κ̂ = (η_(ℓ−1) − η_ℓ)/(J_ℓ − J_(ℓ−1)) where the estimate fell by ≥ MIN_DROP of itself and
    kept its sign, clipped to [KAPPA_MIN, 1]; else the previous κ̂, or 1."""
    k, how = calibrate(1.0, 0.4, 10.0, 10.8, None)                 # fell 60 %: measured 0.6/0.8
    assert k == pytest.approx(0.75) and how == "measured"
    assert calibrate(1.0, 0.4, 10.0, 10.3, None)[0] == 1.0         # over-estimated: not scaled down
    assert calibrate(1.0, 0.9, 10.0, 10.9, 0.5) == (0.5, "previous level's")   # fell 10 %: noise
    assert calibrate(1.0, -0.5, 10.0, 10.9, None) == (1.0, "not measured yet")  # sign changed
    assert calibrate(1.0, 0.2, 10.0, 18.0, None)[0] == adaptive.KAPPA_MIN


@pytest.fixture(scope="module")
def small_run(tmp_path_factory):
    d = annulus(tmp_path_factory.mktemp("annulus"))
    return d, analyze_adaptive(d, rtol=0.01, initial_h_factor=2.0)


@pytest.mark.slow
def test_adaptive_contract_and_nested_levels(small_run):
    """Every FEM figure has an estimate and a method; at least two nested levels, each finer; the
    estimates of the last level are what the results carry; the refinement stopped at --rtol;
    the stiffness of nested conforming meshes only falls (the compliance rises)."""
    design, (res, fields) = small_run
    lv = res["discretization_levels"]
    assert len(lv) >= adaptive.MIN_LEVELS and res["stopped_by"] == "rtol" and res["error_method"] == "adaptive"
    assert all(b["dofs"] > a["dofs"] for a, b in zip(lv, lv[1:]))
    k = [x["torsional_stiffness_Nm_per_rad"] for x in lv]
    assert all(b < a * (1 + 1e-9) for a, b in zip(k, k[1:]))
    for key in ("gauge_strain_per_Nm", "sensitivity_mV_per_V_per_Nm", "torsional_stiffness_Nm_per_rad", "safety_factor"):
        assert f"{key}_error_method" in res and math.isfinite(res[f"{key}_error_estimate"]), key
    rel_k = res["torsional_stiffness_Nm_per_rad_error_estimate"] / res["torsional_stiffness_Nm_per_rad"]
    rel_e = res["gauge_strain_per_Nm_error_estimate"] / abs(res["gauge_strain_per_Nm"])
    assert 0 < rel_k <= 0.01 and 0 < rel_e <= 0.01
    arms = res["gauge_strains_per_Nm_error_estimate"]
    assert set(arms) == {"arm1", "arm2", "arm3", "arm4"}
    assert all(arms[a] <= 0.01 * abs(res["gauge_strains_per_Nm"][a]) for a in arms)
    assert res["dofs"] == lv[-1]["dofs"] and fields.mesh.n_dofs == res["dofs"]
    assert res["torsional_stiffness_Nm_per_rad"] == pytest.approx(k[-1], rel=1e-6)
    assert res["warnings"] == []


@pytest.mark.slow
def test_estimate_covers_the_last_change(small_run):
    """Two-level check: the previous level's error is at least the (exact) change to the last one
    (the compliance of nested spaces rises monotonically), and its stiffness estimate covered it."""
    _, (res, _) = small_run
    a, b = res["discretization_levels"][-2:]
    change = a["torsional_stiffness_Nm_per_rad"] - b["torsional_stiffness_Nm_per_rad"]
    assert a["estimate"]["torsional_stiffness_Nm_per_rad"] >= change > 0


@pytest.mark.parametrize("budget,stop,needle", [
    pytest.param({"max_dofs": 8_000}, "max_dofs", "--max-dofs 8000", marks=pytest.mark.slow),
    ({"max_memory_gb": 0.2}, "memory", "memory budget 0.2 GB")])
def test_a_budget_stops_the_refinement_and_says_which(tmp_path, budget, stop, needle):
    d = annulus(tmp_path, sections=24)
    res, _ = analyze_adaptive(d, rtol=1e-5, initial_h_factor=2.5, **budget)
    assert res["stopped_by"] == stop
    assert any("--rtol 1e-05 not reached" in w and needle in w for w in res["warnings"])
    assert all(math.isfinite(res[f"{k}_error_estimate"]) for k in ("gauge_strain_per_Nm", "torsional_stiffness_Nm_per_rad"))


def test_order_1_falls_back_to_the_levels_and_says_so(tmp_path, monkeypatch):
    """P1 cannot be refined by the P2 bisection: the error method is the levels', with a warning."""
    from flexure import convergence

    d = annulus(tmp_path, sections=24)
    called = {}
    monkeypatch.setattr(convergence, "analyze_with_error",
                        lambda design, size, order, rtol, **kw: (called.setdefault("order", order) and
                                                                 ({"warnings": []}, None)))
    res, _ = convergence.analyze_design(d, order=1, method="adaptive")
    assert called["order"] == 1 and any("adaptive refinement works on order 2" in w for w in res["warnings"])


def test_levels_are_the_default_and_adaptive_is_opt_in(tmp_path, monkeypatch):
    """analyze_design: no method → the levels (adaptive's effectivity is not yet established on
    unseen parts, reports/fem_adaptive.md); "adaptive" → flexure.adaptive; anything else → InputError."""
    from flexure import convergence
    from flexure.errors import InputError

    d = annulus(tmp_path, sections=24)
    calls = []
    monkeypatch.setattr(convergence, "analyze_with_error", lambda *a, **kw: (calls.append("levels") or
                                                                           ({"warnings": []}, None)))
    monkeypatch.setattr(adaptive, "analyze_adaptive", lambda *a, **kw: (calls.append("adaptive") or
                                                                        ({"warnings": []}, None)))
    assert convergence.analyze_design(d, order=2)[0]["error_method"] == "levels"
    convergence.analyze_design(d, order=2, method="adaptive")
    assert calls == ["levels", "adaptive"]
    with pytest.raises(InputError, match="error method"):
        convergence.analyze_design(d, order=2, method="richardson")
