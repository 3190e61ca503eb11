"""The adaptive path's final figures from its goal solve (flexure.goal_cases): every gauge's reading
under the five off-axis load cases from the gauges' duals, ε_g(j) = z_gᵀ b_j, equals reading the
solved load case (symmetric A), for both hub couplings; so the last mesh needs no six-case solve."""

from dataclasses import replace

import numpy as np
import pytest

from skew_annulus import skew_annulus


@pytest.fixture(scope="module")
def mesh_and_design(tmp_path_factory):
    """A 2 mm annulus (r 3 … 10 mm) as an STL with four gauges at unequal radii and skewed axes
    (no symmetry: the off-axis loads give every gauge a reading), meshed coarsely (P2)."""
    from flexure.analysis import build_mesh

    design = skew_annulus(tmp_path_factory.mktemp("goal_cases"))
    return design, build_mesh(design, "coarse", 2, 2.0)


@pytest.mark.parametrize("coupling,direct", [
    ("rigid", True), ("distributed", False),
    pytest.param("rigid", False, marks=pytest.mark.slow), pytest.param("distributed", True, marks=pytest.mark.slow)])
def test_dual_readings_equal_the_solved_load_cases(mesh_and_design, coupling, direct, monkeypatch):
    from flexure import goal_cases, goals
    from flexure import solve as fsolve
    from flexure.analysis import analyze_mesh

    design, mres = mesh_and_design
    design = replace(design, coupling=coupling)
    if not direct:                                      # the p-multigrid CG at the goal tolerance
        monkeypatch.setattr(fsolve, "DIRECT_MAX_DOFS", 100)
    sol = goals.solve_goals(design, mres.mesh)
    ref, _ = analyze_mesh(design, mres, rtol=goals.GOAL_RTOL)
    dual, fields = analyze_mesh(design, mres, cases=goal_cases.from_goals(sol))
    tol = 1e-9 if direct else 1e-5
    assert dual["torsional_stiffness_Nm_per_rad"] == pytest.approx(ref["torsional_stiffness_Nm_per_rad"], rel=tol)
    assert dual["gauge_strain_per_Nm"] == pytest.approx(ref["gauge_strain_per_Nm"], rel=tol)
    assert dual["safety_factor"] == pytest.approx(ref["safety_factor"], rel=tol)
    single = ref["crosstalk_single_arm_percent"]
    assert max(single.values()) > 1.0                   # the off-axis loads are read, not ~0
    for key in ref["crosstalk_percent"]:
        assert dual["crosstalk_single_arm_percent"][key] == pytest.approx(single[key], rel=tol, abs=tol)
        assert abs(dual["crosstalk_percent"][key] - ref["crosstalk_percent"][key]) <= tol * max(single.values())
    assert "duals" in dual["solver"]["solver"] and not dual["warnings"] == ["large_residual"]
    assert np.allclose(fields.u_rated_m, sol.U[:, :, 0] * design.rated_torque_Nm)


def test_goal_solve_algebraic_error_is_far_below_the_targets(mesh_and_design, monkeypatch):
    """The p-multigrid CG's goal values (torque case + duals together, flexure.goals.GOAL_RTOL) against
    a direct solve of the same system: the algebraic error of θ and of every gauge reading is below
    1e-6 relative, 10⁴ times below a 1 % --rtol (and the dual readings of the off-axis cases too)."""
    from flexure import goal_cases, goals
    from flexure import solve as fsolve

    design, mres = mesh_and_design
    direct = goals.solve_goals(design, mres.mesh)
    monkeypatch.setattr(fsolve, "DIRECT_MAX_DOFS", 100)
    cg = goals.solve_goals(design, mres.mesh)
    assert "direct" in direct.info["solver"] and "amg-cg" in cg.info["solver"]
    assert abs(cg.theta - direct.theta) <= 1e-6 * abs(direct.theta)
    assert np.abs(cg.eps - direct.eps).max() <= 1e-6 * np.abs(direct.eps).max()
    wrench = np.eye(6)[[5, 0, 1, 2, 3, 4]]
    read = [goal_cases.from_goals(s)(design, mres.mesh, None, None, None, None, wrench)[1] for s in (cg, direct)]
    assert np.abs(read[0] - read[1]).max() <= 1e-6 * np.abs(read[1]).max()
