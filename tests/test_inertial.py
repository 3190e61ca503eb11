"""Inertial parameters of the planar chain (estimator.inertial): the regressor against the momentum
terms, finite differences of the energies and its own structure; parameter round trips, physical
consistency, the declared uncertainty's covariance against a Monte Carlo; the simulator with a
centre of mass off the link axis; the robot file's new fields."""

import re

import numpy as np
import pytest

from estimator import dynamics as D
from estimator import inertial
from userio.errors import InputError
from estimator.model import ModelUncertainty, RobotModel
from estimator.observer import momentum_terms
from estimator.robot import PAPER_LEG_TOML, Robot, load_robot, paper_leg, robot_from_dict
from userio.files import read_toml


def offset_robot(floating=True):
    return Robot(lengths_m=np.array([0.3, 0.25, 0.2]), com_m=np.array([0.12, 0.1, 0.15]),
                 com_perp_m=np.array([0.025, -0.04, 0.012]),
                 masses_kg=np.array([1.2, 0.7, 0.4]), inertias_kgm2=np.array([0.01, 0.005, 0.002]),
                 base_mass_kg=2.0, base_inertia_kgm2=0.03, floating=floating)


def states(n, T=40, seed=0):
    rng = np.random.default_rng(seed)
    return rng.uniform(-3, 3, (T, n)), rng.normal(0, 3, (T, n))


@pytest.mark.parametrize("robot", [offset_robot(), paper_leg()], ids=["offset", "paper"])
def test_regressor_reproduces_the_momentum_terms_to_round_off(robot):
    q, v = states(robot.n_v)
    tau = np.random.default_rng(1).normal(size=q.shape)
    P, u = momentum_terms(robot, q, v, tau)
    YP, Yu = robot.momentum_regressor(q, v)
    theta = robot.parameters()
    assert YP.shape == (len(q), robot.n_v, len(robot.parameter_names))
    scale = np.abs(P).max() + np.abs(u).max()
    assert np.abs(YP @ theta - P).max() < 1e-14 * scale
    assert np.abs(Yu @ theta - (u - tau)).max() < 1e-14 * scale


def test_compiled_and_numpy_regressors_agree():
    robot = offset_robot()
    q, v = states(robot.n_v, seed=3)
    a = inertial.regressor_numpy(robot, q, v)
    from estimator import model_kernels

    if not model_kernels.available():
        pytest.skip("numba not installed")
    b = model_kernels.momentum_regressor(robot, q, v)
    for x, y in zip(a, b):
        np.testing.assert_allclose(x, y, atol=1e-13)


def test_regressor_columns_are_energy_derivatives():
    """Per parameter column j: Y_P,j = ∂T_j/∂v with T_j = ½ vᵀ M_j(q) v (so Y_P,j(q, v) is linear
    and symmetric in v), and Y_u,j = ∂T_j/∂q − ∂V_j/∂q with V_j the potential's regressor
    (g z for masses, g e_z, g n_z for the first moments): central differences."""
    robot = offset_robot()
    N, n = robot.n_links, robot.n_v
    g = robot.gravity_m_per_s2
    q, v = states(n, T=6, seed=4)
    w = np.random.default_rng(5).normal(size=q.shape)

    def potential(qq):                               # (T, n_θ)
        joints, _ = D.forward_kinematics(robot, qq)
        phi = D.link_angles(robot, qq)
        V = np.zeros((len(qq), 2 + 4 * N))
        V[:, 0] = g * qq[:, 1]
        for i in range(N):
            V[:, 2 + 4 * i] = g * joints[:, i, 1]
            V[:, 3 + 4 * i] = g * -np.cos(phi[:, i])
            V[:, 4 + 4 * i] = g * np.sin(phi[:, i])
        return V

    YP, Yu = robot.momentum_regressor(q, v)
    YPw, _ = robot.momentum_regressor(q, w)
    np.testing.assert_allclose(np.einsum("tkj,tk->tj", YP, w), np.einsum("tkj,tk->tj", YPw, v),
                               atol=1e-12)                 # vᵀ M_j w symmetric
    h = 1e-6
    for k in range(n):
        e = np.zeros(n)
        e[k] = h
        Tp = 0.5 * np.einsum("tkj,tk->tj", robot.momentum_regressor(q + e, v)[0], v)
        Tm = 0.5 * np.einsum("tkj,tk->tj", robot.momentum_regressor(q - e, v)[0], v)
        dV = (potential(q + e) - potential(q - e)) / (2 * h)
        np.testing.assert_allclose(Yu[:, k, :], (Tp - Tm) / (2 * h) - dV, atol=2e-7)


def test_parameters_round_trip_and_consistency():
    robot = offset_robot()
    theta = robot.parameters()
    back = robot.with_parameters(theta)
    for f in ("masses_kg", "com_m", "com_perp_m", "inertias_kgm2"):
        np.testing.assert_allclose(getattr(back, f), getattr(robot, f), rtol=1e-14)
    assert robot.consistency_problems(theta) == []
    assert np.all(robot.consistency_margins(theta) > 0)
    bad = theta.copy()
    bad[5] = 0.5 * bad[2] * (robot.com_m[0] ** 2 + robot.com_perp_m[0] ** 2)   # I_o < m|c|²
    problems = robot.consistency_problems(bad)
    assert any("link 1: inertia about the centre of mass" in p for p in problems)
    assert np.any(robot.consistency_margins(bad) < 0)
    with pytest.raises(InputError, match="link 1: inertia"):
        robot.with_parameters(bad)
    off = theta.copy()
    off[3] = -0.01                                        # COM behind the joint
    assert any("off the link" in p for p in robot.consistency_problems(off))


def test_robot_implements_the_model_protocol():
    robot = paper_leg()
    assert isinstance(robot, RobotModel)
    assert robot.n_base == 3 and robot.n_v == 5 and robot.joint_names == ("q1", "q2")
    assert robot.parameter_names[:3] == ("base.m", "base.I", "link1.m")
    M = robot.mass_matrix(np.zeros((1, 5)))
    assert M.shape == (1, 5, 5)
    assert paper_leg(False).mass_matrix(np.zeros((1, 5))).shape == (1, 5, 5)   # always n_v rows


def test_declared_uncertainty_covariance_matches_a_monte_carlo():
    """Σ_θ = J Σ_p Jᵀ (linearized) against the sample covariance of θ over draws of the physical
    errors at a small σ (where the linearization is exact to a few per cent)."""
    robot = offset_robot()
    unc = ModelUncertainty(mass_rel=0.02, inertia_rel=0.05, com_m=0.002)
    S = robot.parameter_covariance(unc)
    draws = np.array([inertial.perturbed(robot, unc, s).parameters() for s in range(4000)])
    emp = np.cov(draws.T)
    d = np.sqrt(np.diag(S))
    np.testing.assert_allclose(np.sqrt(np.diag(emp)), d, rtol=0.06)
    corr = S / np.outer(d, d)
    assert np.abs(np.corrcoef(draws.T) - corr).max() < 0.08


def test_com_perp_in_the_robot_file(tmp_path):
    data = read_toml(PAPER_LEG_TOML)
    data["link"][0]["com_perp_m"] = 0.004
    robot = robot_from_dict(data, "leg.toml")
    np.testing.assert_array_equal(robot.com_perp_m, [0.004, 0.0])
    assert paper_leg().com_perp_m.tolist() == [0.0, 0.0]
    data["link"][1]["com_perp_m"] = 0.5
    with pytest.raises(InputError, match=re.escape("link[2].com_perp_m: centre of mass 0.5 m off")):
        robot_from_dict(data, "leg.toml")


@pytest.mark.parametrize("table, message", [
    ({"relative": 2.0}, "model_uncertainty.relative: 2 is outside the physical range [0, 1]"),
    ({"mass_rel": 0.05}, "model_uncertainty.inertia_rel: missing field"),
    ({"realtive": 0.05}, "model_uncertainty.realtive: unknown field (did you mean 'relative'?)"),
    ({}, "model_uncertainty.mass_rel: missing field (or give relative for all)"),
])
def test_bad_model_uncertainty_is_named(table, message):
    data = read_toml(PAPER_LEG_TOML)
    data["model_uncertainty"] = table
    with pytest.raises(InputError, match=re.escape(message)):
        robot_from_dict(data, "leg.toml")


def test_written_robot_file_reads_back_with_its_tables(tmp_path):
    robot = offset_robot()
    from dataclasses import replace

    robot = replace(robot, model_uncertainty=ModelUncertainty(0.05, 0.1, 0.003), name="offset")
    k = len(robot.parameter_names)
    ident = {"parameter_names": list(robot.parameter_names), "parameters": robot.parameters(),
             "covariance": np.eye(k) * 1e-8, "logs": [{"path": "a.csv", "sha256": "00"}],
             "statistics": {"condition_number": 12.5}}
    path = tmp_path / "id.toml"
    path.write_text(inertial.robot_toml(robot, ident))
    back = load_robot(path)
    np.testing.assert_allclose(back.parameters(), robot.parameters(), rtol=1e-11)
    assert back.model_uncertainty.com_m == 0.003
    cov, source = back.model_covariance()
    np.testing.assert_allclose(cov, np.eye(k) * 1e-8)
    assert "identification of offset from a.csv" in source
    text = path.read_text().replace("mass_kg = 1.2", "mass_kg = 1.3")
    path.write_text(text)
    with pytest.raises(InputError, match="identification.parameters: link1.m .* edited after"):
        load_robot(path)


def test_simulator_with_an_offset_centre_of_mass_agrees_with_the_dynamics():
    """The simulator's plain-float right-hand side (estimator.sim.fast) = M⁻¹(τ − C q̇ − G) of
    estimator.dynamics (checked against pinocchio in test_dynamics) for a COM off the axis."""
    from estimator.sim import Controller, SimConfig
    from estimator.sim.model import Plant

    robot = offset_robot()
    cfg = SimConfig(robot=robot, controller=Controller(q0_rad=np.array([0.3, -0.5, 0.2]), kp=0.0,
                                                       kd=0.0),
                    mount_stiffness=np.zeros(3), mount_damping=np.zeros(3))
    plant = Plant(cfg)
    q, v = states(robot.n_v, T=5, seed=8)
    for k in range(5):
        y = np.concatenate([q[k], v[k]])
        ddq = plant.rhs1(0.0, y)[robot.n_v:]
        ref = D.forward_dynamics(robot, q[k], v[k], np.zeros(robot.n_v))
        np.testing.assert_allclose(ddq, ref, rtol=1e-10, atol=1e-10)
