"""The URDF robot model: the compiled tree recursion against pinocchio, the momentum law
Ṗ = τ + Cᵀv − G by finite differences, the inertial-parameter regressor, the FT transform and
bad URDF input."""

from __future__ import annotations

import numpy as np
import pytest

pin = pytest.importorskip("pinocchio")

from userio.errors import InputError  # noqa: E402
from estimator.model import RobotModel  # noqa: E402
from estimator.spatial import tree as tree_mod  # noqa: E402
from estimator.spatial.model import UrdfModel, pinocchio_terms  # noqa: E402
from estimator.spatial.robot import load_spatial_robot, robot_from_urdf  # noqa: E402
from tests.spatial_urdf import random_states, random_tree_urdf  # noqa: E402

LEG = "robots/quadruped_leg.toml"


@pytest.fixture(scope="module")
def leg():
    return UrdfModel(load_spatial_robot(LEG))


@pytest.fixture(scope="module", params=[0, 1, 2])
def tree_model(request, tmp_path_factory):
    path = tmp_path_factory.mktemp("urdf") / f"rand{request.param}.urdf"
    path.write_text(random_tree_urdf(request.param, n=5))
    return UrdfModel(robot_from_urdf(path))


def test_is_a_robot_model(leg):
    assert isinstance(leg, RobotModel)
    assert leg.n_v == 9 and leg.joint_names == ("hip_abd", "hip_flex", "knee")
    assert leg.tree.body_names == ("base", "hip", "thigh", "shank")
    assert len(leg.parameter_names) == 40


def test_terms_match_pinocchio_leg(leg):
    q, v, tau = random_states(np.random.default_rng(1), 30, 3, scale=3.0)
    P, u = leg.momentum_terms(q, v, tau)
    P2, u2 = pinocchio_terms(leg.robot, q, v, tau)
    assert np.allclose(P, P2, rtol=0, atol=1e-12 * np.abs(P2).max())
    assert np.allclose(u, u2, rtol=0, atol=1e-12 * np.abs(u2).max())


def test_terms_match_pinocchio_random_trees(tree_model):
    """Trees with prismatic and continuous joints, unaligned axes, a merged fixed link."""
    q, v, tau = random_states(np.random.default_rng(2), 20, 5, scale=2.0)
    P, u = tree_model.momentum_terms(q, v, tau)
    P2, u2 = pinocchio_terms(tree_model.robot, q, v, tau)
    assert np.abs(P - P2).max() < 1e-12 * np.abs(P2).max()
    assert np.abs(u - u2).max() < 1e-12 * np.abs(u2).max()


def test_compiled_equals_python_loop(leg, monkeypatch):
    q, v, tau = random_states(np.random.default_rng(3), 5, 3)
    P, u = leg.momentum_terms(q, v, tau)
    monkeypatch.setattr(tree_mod, "USE_NUMBA", False)
    P2, u2 = leg.momentum_terms(q, v, tau)
    assert np.allclose(P, P2, rtol=1e-14, atol=1e-14) and np.allclose(u, u2, rtol=1e-14, atol=1e-13)


def _qdot(q, v):
    """dq/dt in the log's coordinates: ṗ = v_lin (world), quaternion rate from ω (base frame)."""
    x, y, z, w = q[3:7]
    wx, wy, wz = v[3:6]
    dquat = 0.5 * np.array([w * wx + y * wz - z * wy, w * wy + z * wx - x * wz,
                            w * wz + x * wy - y * wx, -x * wx - y * wy - z * wz])
    return np.r_[v[:3], dquat, v[6:]]


def test_momentum_law_by_finite_differences(tree_model):
    """Ṗ = u for τ from pinocchio's inverse dynamics (rnea) at an arbitrary acceleration:
    P differentiated along q̇(v), v̇ (central differences) against u = τ + Cᵀv − G."""
    model = tree_model.robot.model
    data = model.createData()
    rng = np.random.default_rng(4)
    q, v, _ = random_states(rng, 1, 5)
    q, v = q[0], v[0]
    a = rng.normal(size=v.size)                       # v̇ in the log's coordinates
    R = tree_mod.quat_matrix(q[3:7])
    w = v[3:6]
    vp = np.r_[R.T @ v[:3], v[3:]]
    ap = np.r_[R.T @ a[:3] - np.cross(w, R.T @ v[:3]), a[3:]]
    tau_pin = pin.rnea(model, data, q, vp, ap)
    tau = np.r_[R @ tau_pin[:3], tau_pin[3:]]         # τ = Tᵀ τ_pin
    h = 1e-5
    Ps = []
    for s in (-2, -1, 1, 2):                          # 4th-order central difference
        # integrate q along v for s·h with a small RK4 (the quaternion path is curved)
        dt = s * h
        k1 = _qdot(q, v)
        k2 = _qdot(q + 0.5 * dt * k1, v + 0.5 * dt * a)
        k3 = _qdot(q + 0.5 * dt * k2, v + 0.5 * dt * a)
        k4 = _qdot(q + dt * k3, v + dt * a)
        qs = q + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        P, _ = tree_model.momentum_terms(qs[None], (v + dt * a)[None], np.zeros((1, v.size)))
        Ps.append(P[0])
    Pdot = (Ps[0] - 8 * Ps[1] + 8 * Ps[2] - Ps[3]) / (12 * h)
    _, u = tree_model.momentum_terms(q[None], v[None], tau[None])
    assert np.allclose(Pdot, u[0], rtol=0, atol=1e-7 * np.abs(u).max())


def test_mass_matrix_matches_crba(leg):
    q, _, _ = random_states(np.random.default_rng(5), 3, 3)
    M = leg.mass_matrix(q)
    data = leg.robot.model.createData()
    for k in range(3):
        Mp = pin.crba(leg.robot.model, data, q[k])
        Mp = np.triu(Mp) + np.triu(Mp, 1).T
        T = np.eye(9)
        T[:3, :3] = tree_mod.quat_matrix(q[k, 3:7]).T          # v_pin = T v
        assert np.allclose(M[k], T.T @ Mp @ T, atol=1e-13)


def test_regressor_reproduces_terms_and_pinocchio(tree_model):
    q, v, tau = random_states(np.random.default_rng(6), 10, 5)
    YP, Yu = tree_model.momentum_regressor(q, v)
    th = tree_model.parameters()
    P, u = tree_model.momentum_terms(q, v, tau)
    assert np.allclose(YP @ th, P, atol=1e-12 * np.abs(P).max())
    assert np.allclose(Yu @ th, u - tau, atol=1e-12 * np.abs(u).max())
    model = tree_model.robot.model
    data = model.createData()
    for k in range(3):                  # P = M v is the torque regressor at (q, 0, v) − at (q, 0, 0)
        R = tree_mod.quat_matrix(q[k, 3:7])
        vp = np.r_[R.T @ v[k, :3], v[k, 3:]]
        z = np.zeros_like(vp)
        Y = (pin.computeJointTorqueRegressor(model, data, q[k], z, vp)
             - pin.computeJointTorqueRegressor(model, data, q[k], z, z))
        Y[:3] = R @ Y[:3]
        assert np.allclose(YP[k], Y, atol=1e-12)


def test_with_parameters_and_consistency(leg):
    th = leg.parameters()
    assert leg.consistency_problems(th) == []
    th2 = th.copy()
    th2[10 * 2] *= 1.5                                   # thigh mass ×1.5 (same c: scale mc too)
    th2[10 * 2 + 1:10 * 2 + 4] *= 1.5
    m2 = leg.with_parameters(th2)
    assert np.allclose(m2.parameters(), th2)
    q, v, tau = random_states(np.random.default_rng(7), 4, 3)
    YP, _ = leg.momentum_regressor(q, v)
    assert np.allclose(m2.momentum_terms(q, v, tau)[0], YP @ th2, atol=1e-12)
    bad = th.copy()
    bad[10] = -0.1
    assert any("hip: mass" in p for p in leg.consistency_problems(bad))
    bad = th.copy()
    bad[10 * 3 + 4] = -1.0                               # shank Ixx negative
    assert any("shank" in p and "positive definite" in p for p in leg.consistency_problems(bad))
    bad = th.copy()                                      # Izz > Ixx + Iyy about the CoM
    bad[10 * 3 + 9] += 0.01
    assert any("triangle" in p for p in leg.consistency_problems(bad))


def test_ft_wrench_transform_matches_pinocchio(leg):
    """The sensor-frame wrench ON the robot → base rows: pinocchio's SE3.act on a Force gives
    the same wrench in the base frame; the force row is then rotated to the world."""
    rng = np.random.default_rng(8)
    q, _, _ = random_states(rng, 4, 3)
    w = rng.normal(size=(4, 6))
    rows = leg.base_rows_from_ft(q, w)
    fid = leg.robot.model.getFrameId("ft_sensor")
    X = leg.robot.model.frames[fid].placement
    for k in range(4):
        fb = X.act(pin.Force(w[k, :3], w[k, 3:]))
        R = tree_mod.quat_matrix(q[k, 3:7])
        assert np.allclose(rows[k, :3], R @ fb.linear) and np.allclose(rows[k, 3:], fb.angular)
    assert np.allclose(leg.ft_from_base_rows(q, rows), w)


@pytest.mark.parametrize("text, match", [
    ("<robot name='x'><link name='a'/><joint", "not a readable URDF"),
    ("<robat/>", "root element"),
    ("<robot name='x'><link name='a'/><link name='b'/><joint name='j' type='planar'><parent link='a'/>"
     "<child link='b'/></joint></robot>", "joint 'j': type 'planar'"),
    ("<robot name='x'><link name='a'><collision><geometry><cone radius='1'/></geometry></collision>"
     "</link></robot>", "link 'a' <collision> 1: unsupported geometry <cone>"),
])
def test_bad_urdf_names_file_and_element(tmp_path, text, match):
    p = tmp_path / "bad.urdf"
    p.write_text(text)
    with pytest.raises(InputError, match=match) as exc:
        load_spatial_robot(p)
    assert str(p) in str(exc.value) and "\n" not in str(exc.value)


def test_bad_declaration_names_field(tmp_path):
    import shutil

    shutil.copy("robots/quadruped_leg.urdf", tmp_path / "leg.urdf")
    decl = tmp_path / "leg.toml"
    decl.write_text('urdf = "leg.urdf"\nft_frame = "ft_sensr"\n')
    with pytest.raises(InputError, match="ft_frame: no frame 'ft_sensr'.*did you mean 'ft_sensor'"):
        load_spatial_robot(decl)
    decl.write_text('urdf = "leg.urdf"\nft_frame = "thigh"\n')
    with pytest.raises(InputError, match="ft_frame: 'thigh' moves with joint 'hip_flex'"):
        load_spatial_robot(decl)
    decl.write_text('urdf = "leg.urdf"\ntorque_sensed = ["kne"]\n')
    with pytest.raises(InputError, match="torque_sensed: joint 'kne'"):
        load_spatial_robot(decl)
    decl.write_text('urdf = "nope.urdf"\n')
    with pytest.raises(InputError, match="urdf: file .*nope.urdf not found"):
        load_spatial_robot(decl)
