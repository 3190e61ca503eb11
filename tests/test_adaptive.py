"""The adaptive, goal-oriented analysis (flexure.adaptive): its stopping rules, the two-level
calibration of the estimate, and the output contract, on a small annulus STL (fast)."""

import math

import numpy as np
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
load_radius_max_mm = {load_max}
fixed_radius_min_mm = {fixed_min}
[mesh]
size = "coarse"
order = 2
"""


def annulus(tmp_path, sections: int = 48, load_max_mm: float = 3.02, fixed_min_mm: float = 9.9):
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
    (tmp_path / "annulus.toml").write_text(ANNULUS.format(gauges="\n".join(gauges), load_max=load_max_mm,
                                                         fixed_min=fixed_min_mm))
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
    # at least two levels (0.005 stopped on the first mesh: MIN_LEVELS = 1 with the enriched estimate; 0.004
    # takes three: 6.1k, 12.8k, 29.1k dofs). Not a coarser start: at h × 2.5 the 48-gon's first mesh (2.8k dofs)
    # leaves 16 nodes off the STL, 902 by the fourth level, and the stiffness rises by 1 % as they are moved
    # (the domain changes between levels: measured 2026-11-26). The memory budget is of this whole test process.
    return d, analyze_adaptive(d, rtol=0.004, max_memory_gb=8.0)


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
    assert 0 < rel_k <= 0.004 and 0 < rel_e <= 0.004
    arms = res["gauge_strains_per_Nm_error_estimate"]
    assert set(arms) == {"arm1", "arm2", "arm3", "arm4"}
    rel_scale = sum(abs(v) for v in res["gauge_strains_per_Nm"].values()) / 4      # adaptive._strain_scales
    assert all(arms[a] <= 0.004 * max(abs(res["gauge_strains_per_Nm"][a]), rel_scale) for a in arms)
    assert res["dofs"] == lv[-1]["dofs"] and fields.mesh.n_dofs == res["dofs"]
    assert res["torsional_stiffness_Nm_per_rad"] == pytest.approx(k[-1], rel=1e-6)
    assert res["warnings"] == []


@pytest.mark.slow
def test_estimate_covers_the_last_change(small_run):
    """Two-level check: each level's error is at least the (exact) change to the next one (the
    compliance of nested spaces rises monotonically), and its stiffness estimate covered it."""
    _, (res, _) = small_run
    lv = res["discretization_levels"]
    assert len(lv) >= 2
    for a, b in zip(lv, lv[1:]):
        change = a["torsional_stiffness_Nm_per_rad"] - b["torsional_stiffness_Nm_per_rad"]
        assert a["estimate"]["torsional_stiffness_Nm_per_rad"] >= change > 0


def test_a_refinement_left_folded_stops_at_the_last_valid_level(tmp_path, monkeypatch):
    """A refinement whose projection leaves elements flat or inverted (refine.straighten_invalid cannot mend
    them) is not solved on: the run answers with the level before it and says why."""
    import flexure.refine as refine

    real = refine.bisect

    def folded(*a, **k):
        out, fields, info = real(*a, **k)
        return out, fields, {**info, "invalid_elements": 3}

    monkeypatch.setattr(refine, "bisect", folded)
    res, _ = analyze_adaptive(annulus(tmp_path, sections=24), rtol=1e-5, initial_h_factor=2.5)
    assert res["stopped_by"] == "invalid_mesh" and len(res["discretization_levels"]) == 1
    assert any("not reached" in w and "3 elements" in w and "flat or inverted" in w for w in res["warnings"])
    assert all(math.isfinite(res[f"{k}_error_estimate"]) for k in ("gauge_strain_per_Nm", "torsional_stiffness_Nm_per_rad"))


@pytest.mark.parametrize("budget,stop,needle", [
    pytest.param({"max_dofs": 8_000}, "max_dofs", "--max-dofs 8000", marks=pytest.mark.slow),
    ({"max_memory_gb": 0.2}, "memory", "memory budget 0.2 GB"),
    ({"max_seconds": 1e-3}, "time", "time budget 0.001 s")])
def test_a_budget_stops_the_refinement_and_says_which(tmp_path, budget, stop, needle):
    d = annulus(tmp_path, sections=24)
    res, _ = analyze_adaptive(d, rtol=1e-5, initial_h_factor=2.5, **budget)
    assert res["stopped_by"] == stop
    assert any("--rtol 1e-05 not reached" in w and needle in w for w in res["warnings"])
    assert all(math.isfinite(res[f"{k}_error_estimate"]) for k in ("gauge_strain_per_Nm", "torsional_stiffness_Nm_per_rad"))


def test_an_estimate_whose_enriched_solve_did_not_converge_is_withheld_and_stops_the_run(tmp_path, monkeypatch):
    """The enriched CG short of its tolerance at its cap (as on a near-incompressible material): the run stops
    on that level, says why, and gives the figures without a ± (NaN), never the unconverged iterate's."""
    from flexure import enriched

    monkeypatch.setattr(enriched, "LEVEL_MAX_ITER", 1)
    res, _ = analyze_adaptive(annulus(tmp_path, sections=24), rtol=1e-3, initial_h_factor=2.5)
    assert res["stopped_by"] == "unconverged" and len(res["discretization_levels"]) == 1
    assert res["discretization_levels"][0]["enriched"]["converged"] is False
    assert any("no error estimate" in w and "did not converge in 1 iterations" in w for w in res["warnings"])
    for k in ("torsional_stiffness_Nm_per_rad", "gauge_strain_per_Nm", "sensitivity_mV_per_V_per_Nm"):
        assert math.isfinite(res[k]) and math.isnan(res[f"{k}_error_estimate"])
        assert "withheld" in res[f"{k}_error_method"]
    assert all(math.isnan(v) for v in res["gauge_strains_per_Nm_error_estimate"].values())


def test_a_time_budget_that_is_not_reached_changes_nothing(small_run):
    """A budget far above the run's time: the same levels, figures and estimates as without one; the
    seconds per DOF and the time cap recorded where a next level was sized."""
    d, (res, _) = small_run
    res_t, _ = analyze_adaptive(d, rtol=0.004, max_memory_gb=8.0, max_seconds=1e6)
    assert res_t["stopped_by"] == res["stopped_by"] == "rtol" and res_t["max_seconds"] == 1e6
    assert [lv["dofs"] for lv in res_t["discretization_levels"]] == [lv["dofs"] for lv in res["discretization_levels"]]
    for k in ("torsional_stiffness_Nm_per_rad", "gauge_strain_per_Nm"):
        assert res_t[k] == res[k] and res_t[f"{k}_error_estimate"] == res[f"{k}_error_estimate"]
    sized = [lv["sizing"] for lv in res_t["discretization_levels"] if lv.get("sizing")]
    assert sized and all(s["seconds_per_dof"] > 0 and s["time_cap_dofs"] > s["next_dofs"] for s in sized)


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


def test_adaptive_is_the_default_and_the_levels_are_asked_for(tmp_path, monkeypatch):
    """analyze_design: no method → flexure.adaptive (DEFAULT_METHOD); "levels" → the levels'
    Richardson (the cross-check); anything else → InputError."""
    from flexure import convergence
    from userio.errors import InputError

    d = annulus(tmp_path, sections=24)
    calls = []
    monkeypatch.setattr(convergence, "analyze_with_error", lambda *a, **kw: (calls.append("levels") or
                                                                           ({"warnings": []}, None)))
    monkeypatch.setattr(adaptive, "analyze_adaptive", lambda *a, **kw: (calls.append("adaptive") or
                                                                        ({"warnings": []}, None)))
    convergence.analyze_design(d, order=2)
    assert convergence.analyze_design(d, order=2, method="levels")[0]["error_method"] == "levels"
    assert calls == ["adaptive", "levels"]
    with pytest.raises(InputError, match="error method"):
        convergence.analyze_design(d, order=2, method="richardson")


def annulus_gauge_exact(design, thickness_m: float = 3e-3, torque_Nm: float = 1.0):
    """The annulus's exact gauge read-outs (flexure.exact: the torsion field u_θ = B/r − Br/b²)."""
    from flexure.exact import annulus_gauge_exact as exact

    return exact(design, thickness_m, torque_Nm)


@pytest.fixture(scope="module")
def round_annulus_run(tmp_path_factory):
    """The annulus with a 192-sided polygon (within 1.3e-4 of the circle), adaptive at --rtol 0.01."""
    d = annulus(tmp_path_factory.mktemp("round_annulus"), sections=192)
    return d, analyze_adaptive(d, rtol=0.01)


@pytest.mark.slow
@pytest.mark.xfail(strict=True, reason=(
    "measured 2026-11-26 17:40-18:00 UTC (benchmarks/fem_geometry_error.py round, load 5-8): --rtol 0.01 stops at "
    "7.1 k dofs; every boundary node on the STL (0 pending), the P2 faces within 1.3 um of the facets; the goals' "
    "geometric error (shape derivative, flexure.geometry_error) 0.0001-0.014 %, added to the estimate. Arms' "
    "effectivities 2.03 (k), 1.97, 14.9, 1.72, 1.95, bridge 1.94 against the polygon's own reference (the circle's "
    "strains; k x (1 - pi^2/(3 N^2))^2): arm 2's P2 error is 0.001 % at a sign change (L0 -0.027 %), its enriched "
    "change 0.011 %: saturation, not geometry (the 48-gon, whose geometric error is 0.03-0.07 %, brackets in "
    "[1.31, 2.08] with it, [0.88, 2.89] without)"))
def test_gauge_estimates_bracket_the_exact_torsion_strain(round_annulus_run):
    """Against the exact read-outs of the torsion field (``annulus_gauge_exact``: no reference run,
    no allowance): every arm's estimate covers its true error and is at most 3× conservative, the
    bridge strain's too."""
    import numpy as np

    design, (res, _) = round_annulus_run
    exact = annulus_gauge_exact(design)
    arms = [g.arm for g in design.gauges]
    got = np.array([res["gauge_strains_per_Nm"][f"arm{a}"] for a in arms])
    est = np.array([res["gauge_strains_per_Nm_error_estimate"][f"arm{a}"] for a in arms])
    true = np.abs(got - exact)
    assert np.all(est >= true) and np.all(est <= 3.0 * true), est / true
    ref = float(np.mean(np.abs(exact)))
    e_ref = abs(abs(res["gauge_strain_per_Nm"]) - ref)
    assert e_ref <= res["gauge_strain_per_Nm_error_estimate"] <= 3.0 * e_ref


def _fem_annulus():
    from benchmark_module import benchmark_module

    return benchmark_module("fem_annulus", "fem_annulus")


@pytest.mark.slow
@pytest.mark.parametrize("part", ["round", "thin"])
def test_enriched_estimate_brackets_the_exact_torsion_field(tmp_path, part):
    """On exact geometry (a STEP of circles; load and clamp on the bore and rim faces alone, so the
    torsion field u_θ = B/r − Br/b² is the exact solution of the discrete problem), --rtol 0.01:
    every goal's estimate on every level (stiffness, each gauge, the bridge strain) covers its true
    error and is at most 3× conservative. Measured 2026-11-26 (benchmarks/fem_annulus.py
    --exact-bands): round 1.88-2.15 (arms), 2.06 (k), 1.70 (bridge); thin (arms 30-65° off the
    radial, no symmetry) 1.98-2.03, 2.15, 1.92."""
    import numpy as np

    fa = _fem_annulus()
    design = fa.make_part(tmp_path, part, "step", exact_bands=True)
    exact = annulus_gauge_exact(design, thickness_m=fa.PARTS[part]["t"] * 1e-3)
    k_ex = fa.stiffness_exact(part, design.material.shear_modulus_Pa)
    s = np.array([adaptive.ARM_SIGN[g.arm] for g in design.gauges])
    res, _ = analyze_adaptive(design, rtol=0.01)
    assert res["stopped_by"] == "rtol"
    for lv in res["discretization_levels"]:
        est = lv["estimate"]
        eff_arms = np.array(est["gauge_strains"]) / np.abs(np.array(lv["gauge_strains"]) - exact)
        eff_k = est["torsional_stiffness_Nm_per_rad"] / abs(lv["torsional_stiffness_Nm_per_rad"] - k_ex)
        eff_b = est["gauge_strain_per_Nm"] / abs(lv["gauge_strain_per_Nm"] - s @ exact / 4)
        eff = np.r_[eff_arms, eff_k, eff_b]
        assert np.all((eff >= 1.0) & (eff <= 3.0)), (lv["level"], eff)


@pytest.mark.slow
def test_adaptive_answer_is_within_rtol_of_the_exact_torsion_strain(round_annulus_run):
    """--rtol 0.01 on the round annulus: every arm's read-out and the bridge strain within 1 % of the
    exact torsion field's (``annulus_gauge_exact``), and the refinement says it stopped at --rtol."""
    import numpy as np

    design, (res, _) = round_annulus_run
    exact = annulus_gauge_exact(design)
    got = np.array([res["gauge_strains_per_Nm"][f"arm{g.arm}"] for g in design.gauges])
    assert res["stopped_by"] == "rtol"
    assert np.all(np.abs(got - exact) <= 0.01 * np.abs(exact)), (got - exact) / exact
    assert abs(abs(res["gauge_strain_per_Nm"]) - np.mean(np.abs(exact))) <= 0.01 * np.mean(np.abs(exact))


def test_bridge_estimate_bounds_through_its_arms():
    """The arms' DWR estimates cancel in the bridge's own sum (η = +1, −1 … with signs +, +: Σ s_i η_i
    = 0); the bridge's estimate is still Σ |s_i| e_i / 4 of the arms' estimates, so it bounds the
    bridge's error wherever theirs bound the arms'."""
    from types import SimpleNamespace

    design = SimpleNamespace(gauges=[SimpleNamespace(arm=a) for a in (1, 2, 3, 4)])
    rec = {"theta": 1e-3, "torsional_stiffness_Nm_per_rad": 1e3, "gauge_strain_per_Nm": 1e-5,
           "gauge_strains": [1e-5, -1e-5, 1e-5, -1e-5],
           "eta": {"theta": 1e-6, "gauges": [2e-8, 2e-8, -2e-8, -2e-8], "eps_ref": 0.0}}
    out = adaptive._estimates(rec, None, {}, design)
    arms = out["estimate"]["gauge_strains"]
    assert arms == pytest.approx([adaptive.SAFETY * 2e-8] * 4)
    assert out["estimate"]["gauge_strain_per_Nm"] == pytest.approx(sum(arms) / 4) and sum(arms) > 0


def test_enriched_estimate_measures_the_saturation_ratio_between_levels():
    """Synthetic nested levels with known errors: the P2 errors E_ℓ (θ, bridge, four arms), the enriched
    ones q E_ℓ with q = 0.5 (re-entrant: V⁺ only halves the error). Level 0 reports 2.7|d| = 2.7(1 − q)|E|
    (q unmeasured: a re-entrant edge's 4/9); level 1 measures q̂ = 0.5 per goal and reports
    max(2, 1.5/(1 − q̂))|d| = 1.5 |E|; an arm whose enriched difference changed sign keeps 2.7|d|, here
    (its error near zero) held at the gauge set's q (½) × the median of the arms' (saturation.arm_floor)."""
    q, J = 0.5, np.array([1e-3, 1e-5, 1e-5, -1e-5, 1e-5, -1e-5])      # θ, bridge, arms (exact)
    E0 = np.array([2e-5, 1e-7, 3e-7, -2e-7, 1e-7, -2e-7])
    E1 = 0.4 * E0
    E1[5] = 1e-9                                                       # arm 4 crosses zero

    def level(E):
        Jh, d = J - E, (1 - q) * E
        return {"theta": Jh[0], "torsional_stiffness_Nm_per_rad": 1 / Jh[0], "gauge_strain_per_Nm": Jh[1],
                "gauge_strains": Jh[2:].tolist(), "goal_algebraic_error": 1e-8,
                "enriched": {"theta": d[0], "eps_ref": d[1], "gauges": d[2:].tolist()}}

    l0, l1 = level(E0), level(E1)
    seen = {}
    e0 = adaptive._enriched_estimates(l0, None, seen)
    assert e0["estimate"]["gauge_strains"] == pytest.approx((2.7 * (1 - q) * np.abs(E0[2:])).tolist())
    assert seen == {}                                  # nothing measured on a first level
    e1 = adaptive._enriched_estimates(l1, l0, seen)
    assert e1["kappa"]["theta"] == pytest.approx(q) and e1["kappa"]["g0"] == pytest.approx(q)
    assert e1["estimate"]["gauge_strain_per_Nm"] == pytest.approx(1.5 * abs(E1[1]))
    assert e1["estimate"]["gauge_strains"][:3] == pytest.approx((1.5 * np.abs(E1[2:5])).tolist())
    floor = 0.5 * np.median([1.5 * abs(E1[2]), 1.5 * abs(E1[3]), 1.5 * abs(E1[4]), 2.7 * (1 - q) * abs(E1[5])])
    assert e1["estimate"]["gauge_strains"][3] == pytest.approx(floor) and floor > 2.7 * (1 - q) * abs(E1[5])
    assert "changed sign" in e1["kappa_how"]["g3"] and "floor" in e1["kappa_how"]["g3"] and set(seen) == {"theta", "eps_ref", "g0", "g1", "g2"}
    k_rel = e1["estimate"]["torsional_stiffness_Nm_per_rad"] / l1["torsional_stiffness_Nm_per_rad"]
    assert k_rel == pytest.approx(1.5 * abs(E1[0]) / abs(l1["theta"]))


def test_bridge_estimate_adds_its_arms_saturation_differences():
    """Bridge ε_ref = Σ s_i ε_i / 4 with arms whose enriched spaces saturate differently (q_i ∈ [−0.3, 0.6],
    drifting by ≤ 0.1, errors falling by r_i ∈ [0.2, 0.5] per level, random signs): the bridge's own q̂ mixes
    the arms' and misses (< 1) on a share of them; adding Σ |s_i d_i| |f_i − f_ref| / 4 (saturation.bridge_estimate) it is never
    below the arms' estimates combined with their signs, |Σ s_i f_i d_i| / 4, and misses far less often.
    Where every arm has the bridge's factor (one level: the same unmeasured q) it is the bridge's own, unless
    an arm is held at the gauge set's floor (saturation.arm_floor): then it is not below it."""
    rng = np.random.default_rng(7)
    signs, Je = np.array([1.0, -1.0, 1.0, -1.0]), np.array([1e-5, -1e-5, 1e-5, -1e-5])

    def level(E, q):
        Jh, d = Je - E, (1 - q) * E
        return {"theta": 1e-3, "torsional_stiffness_Nm_per_rad": 1e3, "gauge_strain_per_Nm": float(signs @ Jh / 4),
                "gauge_strains": Jh.tolist(), "goal_algebraic_error": 1e-8,
                "enriched": {"theta": 1e-6, "eps_ref": float(signs @ d / 4), "gauges": d.tolist()}}

    own, new = [], []
    for _ in range(1000):
        E0, q0, r = rng.normal(size=4) * 1e-7, rng.uniform(-0.3, 0.6, 4), rng.uniform(0.2, 0.5, 4)
        q1 = np.clip(q0 + rng.uniform(-0.1, 0.1, 4), -0.3, 0.6)
        l0, l1 = level(E0, q0), level(r * E0, q1)
        full, first_own = (adaptive._enriched_estimates(l0, None, {}, s) for s in (signs, None))
        first, first_own = full["estimate"], first_own["estimate"]
        if any("floor" in how for how in full["kappa_how"].values()):    # an arm held above its own (3)
            assert first["gauge_strain_per_Nm"] >= first_own["gauge_strain_per_Nm"] * (1 - 1e-12)
        else:
            assert first["gauge_strain_per_Nm"] == pytest.approx(first_own["gauge_strain_per_Nm"])
        E_ref = abs(signs @ (r * E0)) / 4
        if E_ref < 0.1 * np.abs(r * E0).mean():
            continue                                            # a bridge whose arms' errors cancel
        seen = {}
        adaptive._enriched_estimates(l0, None, seen, signs)
        own.append(adaptive._enriched_estimates(l1, l0, dict(seen))["estimate"]["gauge_strain_per_Nm"] / E_ref)
        out = adaptive._enriched_estimates(l1, l0, dict(seen), signs)["estimate"]
        new.append(out["gauge_strain_per_Nm"] / E_ref)
        d = np.array(l1["enriched"]["gauges"])
        assert out["gauge_strain_per_Nm"] >= abs(signs @ (np.sign(d) * np.array(out["gauge_strains"]))) / 4 * (1 - 1e-12)
    own, new = np.array(own), np.array(new)
    assert np.mean(own < 1) > 0.04 and np.mean(new < 1) < 0.02 and np.all(new >= own * (1 - 1e-12))


@pytest.fixture(scope="module")
def small_tagged(tmp_path_factory):
    """A coarse annulus STL (24 sides) meshed by gmsh, tagged, its projector (no solve)."""
    d = annulus(tmp_path_factory.mktemp("tagged"), sections=24)
    mres = adaptive.start_mesh(d, initial_h_factor=2.5)
    tm, projector = adaptive.geometry(d, mres)
    return d, tm, projector


def test_stl_boundary_vertices_and_mid_nodes_are_put_on_the_stl(small_tagged):
    """gmsh re-parametrises an STL's patches and leaves the vertices off the facets; the snap puts
    the boundary vertices and the boundary mid-edge nodes on the STL (isoparametric P2), and the
    quarter points of the curved boundary edges are then off it by far less than their sagitta."""
    import numpy as np

    from flexure.refine import boundary_geometry_error, snap, vertex_targets

    _, tm, projector = small_tagged
    assert projector.snap_vertices
    info = snap(tm, projector, vertices=True)
    assert info["projection_undone"] == 0 and info.get("vertices_projection_undone", 0) == 0
    # every boundary node on the STL at once (refine.morph: the interior moved with them), none left
    # pending. Measured 2026-11-26: 0 of 816 boundary nodes on this start mesh (its bore resolved as a
    # curve from the STL's folds, adaptive.start_mesh), where projecting the boundary nodes alone on
    # the uncurved start left 17 of 684 partly moved
    assert len(tm.pending[0]) == 0 and info["projection_partial"] == 0
    nodes = np.setdiff1d(np.union1d(vertex_targets(tm)[0], tm.mesh.boundary_nodes()), tm.pending[0])
    P = tm.mesh.points[nodes]
    assert np.abs(projector.project(P) - P).max() < 1e-9
    e, dist, R = boundary_geometry_error(tm, projector)
    assert len(e) and np.isfinite(dist).all() and (R > 0).all()
    # every boundary vertex of the bore on the 24-gon's faces: r between its inradius and circumradius
    X = tm.mesh.points[vertex_targets(tm)[0]]
    r = np.hypot(X[:, 0], X[:, 1])
    inner = r[(r < 6.5e-3) & (X[:, 2] > 1e-9) & (X[:, 2] < 3e-3 - 1e-9)]      # on the bore, off the faces
    assert inner.min() >= 3e-3 * np.cos(np.pi / 24) - 1e-12 and inner.max() <= 3e-3 + 1e-12


def test_nested_bands_keep_the_dirichlet_set_as_the_mesh_is_refined(small_tagged):
    """The load/fixed sets of a refined mesh (the first mesh's set indicators prolongated by the
    bisection) reach no farther than on the first mesh (the load set's largest radius, the fixed
    set's smallest) and hold the first mesh's nodes; re-selecting by the radius bands on the
    refined mesh gives another set."""
    import numpy as np

    from flexure.analysis import _selections
    from flexure.refine import bisect, snap

    d, tm, projector = small_tagged
    snap(tm, projector, vertices=True)
    sets0 = _selections(d, tm.mesh)
    bands = adaptive._band_indicator(tm.mesh, sets0)
    r = np.hypot(*(tm.mesh.points[:, :2].T))
    near = np.flatnonzero((r > 9.0e-3) | (r < 4.0e-3))               # refine along both bands
    elems = np.flatnonzero(np.isin(tm.mesh.tets[:, :4], near).any(axis=1))
    tm1, (bands1,), _ = bisect(tm, elems, [bands], rounds=2, projector=projector)
    load1, fixed1 = adaptive._nested_selections(tm1.mesh, bands1)
    r1 = np.hypot(*(tm1.mesh.points[:, :2].T))
    assert set(sets0[0]) <= set(load1) and set(sets0[1]) <= set(fixed1)
    # the load set reaches no farther out than its first nodes (r is convex: its largest value over a
    # face is at a node); the fixed set no farther in than its first faces, whose chords between rim
    # nodes dip below those nodes (measured 2026-11-26: a bottom-face node at 9.9100 mm inside a clamped
    # first face whose nodes are ≥ 9.9120 mm; the face itself comes to 9.9095 mm)
    assert r1[load1].max() <= r[sets0[0]].max() + 1e-9
    assert r1[fixed1].min() >= _closest_to_axis(tm.mesh, sets0[1]) - 1e-9
    assert len(load1) > len(sets0[0]) and len(fixed1) > len(sets0[1])          # the refined faces' nodes
    # re-selecting by the band would change the set: a clamped first face's mid node (on a chord, inside
    # its vertices' radii) becomes a vertex when its edge is bisected, and a band edge between the two
    # radii (the same first set: the band tests vertices) frees it; the Dirichlet set would move as the
    # mesh is refined (measured 2026-11-26: vertices at 9.9145 mm and up on the first mesh, 9.9120 mm after)
    from dataclasses import replace

    def vertex_min_r(mesh, nodes):
        v = np.zeros(mesh.n_nodes, bool)
        v[mesh.corner_tets] = True
        x = mesh.points[nodes[v[nodes]]]
        return np.hypot(x[:, 0], x[:, 1]).min()

    lo, hi = vertex_min_r(tm1.mesh, fixed1), vertex_min_r(tm.mesh, sets0[1])
    assert lo < hi
    d_edge = replace(d, fixed_radius_min_m=0.5 * (lo + hi))
    assert set(_selections(d_edge, tm.mesh)[1]) == set(sets0[1])
    assert set(_selections(d_edge, tm1.mesh)[1]) < set(fixed1)

def _closest_to_axis(mesh, nodes) -> float:
    """The smallest distance (m) from the z axis over the straight boundary triangles whose nodes
    are all in ``nodes`` (in the xy-plane: the closest point of each projected triangle to the origin)."""
    import numpy as np
    from trimesh.triangles import closest_point

    faces = mesh.boundary_faces()
    inset = np.zeros(mesh.n_nodes, bool)
    inset[nodes] = True
    tri = mesh.points[faces[inset[faces].all(axis=1)][:, :3]] * 1e3           # mm (trimesh's tolerances)
    tri[:, :, 2] = 0.0
    flat = np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1) > 1e-9
    tri = tri[flat]                                                             # the rim's faces project to segments
    cp = closest_point(tri, np.zeros((len(tri), 3)))
    seg = mesh.points[faces[inset[faces].all(axis=1)][:, :3]][~flat] * 1e3
    r_seg = np.hypot(seg[..., 0], seg[..., 1]).min(initial=np.inf)
    return float(min(np.hypot(cp[:, 0], cp[:, 1]).min(initial=np.inf), r_seg)) / 1e3
