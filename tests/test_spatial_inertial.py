"""Inertial parameters of a URDF robot (estimator.spatial.inertial, UrdfModel): consistency margins
against the pseudo-inertia's eigenvalues and ``consistency_problems``, the declared uncertainty's
covariance against finite differences and a Monte Carlo of its physical draws, the robot TOML's
[model_uncertainty] and [identification] tables."""

from __future__ import annotations

import re
import shutil

import numpy as np
import pytest

pin = pytest.importorskip("pinocchio")

from userio.errors import InputError  # noqa: E402
from estimator.model import ModelUncertainty, RobotModel  # noqa: E402
from estimator.spatial import inertial as si  # noqa: E402
from estimator.spatial.model import UrdfModel  # noqa: E402
from estimator.spatial.robot import load_spatial_robot, robot_from_urdf  # noqa: E402
from tests.spatial_urdf import random_tree_urdf  # noqa: E402

LEG = "robots/quadruped_leg.toml"


@pytest.fixture(scope="module")
def leg():
    return UrdfModel(load_spatial_robot(LEG))


@pytest.fixture(scope="module")
def tree(tmp_path_factory):
    """Inertias with rotated principal axes and off-origin centres of mass, a merged fixed link."""
    path = tmp_path_factory.mktemp("urdf") / "rand.urdf"
    path.write_text(random_tree_urdf(5, n=4))
    model = UrdfModel(robot_from_urdf(path))
    rng = np.random.default_rng(5)                # the helper's random inertias may break the
    NB = len(model.tree.body_names)               # triangle inequality: consistent ones here
    from scipy.spatial.transform import Rotation

    R = Rotation.random(NB, random_state=rng).as_matrix()
    d = rng.uniform(1e-4, 3e-3, (NB, 3))
    th = si.from_physical(rng.uniform(0.2, 2.0, NB), rng.normal(0, 0.05, (NB, 3)),
                          np.einsum("bik,bk,bjk->bij", R, d, R))
    return model.with_parameters(th)


def pseudo_inertia_min_eig(theta) -> np.ndarray:
    """λ_min of J = [[½ tr(I_o) 1 − I_o, h], [hᵀ, m]] per body (Wensing et al. 2017), built directly
    from pinocchio's parameter order, independent of the module under test."""
    out = []
    for th in np.asarray(theta).reshape(-1, 10):
        m, h = th[0], th[1:4]
        Io = np.array([[th[4], th[5], th[7]], [th[5], th[6], th[8]], [th[7], th[8], th[9]]])
        J = np.zeros((4, 4))
        J[:3, :3] = 0.5 * np.trace(Io) * np.eye(3) - Io
        J[:3, 3] = J[3, :3] = h
        J[3, 3] = m
        out.append(np.linalg.eigvalsh(J)[0])
    return np.array(out)


def test_the_urdf_robot_is_a_robot_model(leg):
    assert isinstance(leg, RobotModel)
    assert len(leg.consistency_margin_names) == leg.consistency_margins(leg.parameters()).size == 24


@pytest.mark.parametrize("which", ["leg", "tree"])
def test_the_files_parameters_have_positive_margins(which, leg, tree):
    model = leg if which == "leg" else tree
    th = model.parameters()
    assert np.all(model.consistency_margins(th) > 0)
    assert model.consistency_problems(th) == []


def _named(model, theta, body):
    names = model.consistency_margin_names
    g = model.consistency_margins(theta)
    return {n.split(": ", 1)[1]: x for n, x in zip(names, g) if n.startswith(body + ":")}


def test_each_violation_makes_its_own_margin_negative(leg):
    th = leg.parameters()
    bad = th.copy()
    bad[10] = -0.1                                               # hip mass < 0
    assert _named(leg, bad, "hip")["mass > 0"] < 0
    assert all(v > 0 for v in _named(leg, bad, "thigh").values())

    bad = th.copy()
    bad[30 + 4] = -1e-3                                          # shank Ixx: I_c not positive
    g = _named(leg, bad, "shank")
    assert g["mass > 0"] > 0 and min(v for k, v in g.items() if k.startswith("I_c")) < 0
    assert any("positive definite" in p for p in leg.consistency_problems(bad))

    bad = th.copy()
    bad[30 + 9] += 0.01                                          # shank Izz > Ixx + Iyy (about c)
    g = _named(leg, bad, "shank")
    assert all(v > 0 for k, v in g.items() if not k.startswith("triangle"))
    assert min(v for k, v in g.items() if k.startswith("triangle")) < 0
    assert [p for p in leg.consistency_problems(bad) if "triangle" in p]


def test_margins_agree_with_the_pseudo_inertia_and_the_problems(tree):
    """Random θ around the file's (half of them inconsistent): all margins of a body ≥ 0 exactly
    when its pseudo-inertia J ⪰ 0 and exactly when ``consistency_problems`` names nothing."""
    rng = np.random.default_rng(1)
    th0 = tree.parameters()
    names = tree.tree.body_names
    n_bad = 0
    for _ in range(300):
        th = th0 * (1 + 10 ** rng.uniform(-2.5, 0) * rng.standard_normal(th0.size))
        g = tree.consistency_margins(th).reshape(-1, 6)
        ok_margin = np.all(g >= 0, axis=1)
        ok_J = (pseudo_inertia_min_eig(th) >= 0) & (th.reshape(-1, 10)[:, 0] > 0)
        problems = tree.consistency_problems(th)
        ok_prob = np.array([not any(p.startswith(b + ":") for p in problems) for b in names])
        np.testing.assert_array_equal(ok_margin, ok_J)
        np.testing.assert_array_equal(ok_margin, ok_prob)
        n_bad += int((~ok_margin).sum())
    assert 0.2 < n_bad / (300 * len(names)) < 0.8


def test_margins_are_invariant_to_the_body_frames_orientation(tree):
    """Rotating a body's frame (I_o → R I_o Rᵀ, h → R h) leaves its margins unchanged."""
    th = tree.parameters()
    m, h, Io = si.unpack(th)
    from scipy.spatial.transform import Rotation

    R = Rotation.from_rotvec([0.3, -1.1, 0.7]).as_matrix()
    rot = si.pack(m, h @ R.T, R @ Io @ R.T)
    np.testing.assert_allclose(tree.consistency_margins(rot), tree.consistency_margins(th), rtol=1e-9)


@pytest.mark.parametrize("which", ["leg", "tree"])
def test_physical_round_trip_and_jacobian_by_finite_differences(which, leg, tree):
    model = leg if which == "leg" else tree
    th = model.parameters()
    m, c, d, R = si.physical(th)
    Sc = np.einsum("bik,bk,bjk->bij", R, d, R)
    np.testing.assert_allclose(si.from_physical(m, c, Sc), th, atol=1e-14)
    J = si.jacobian(th)

    def theta_of(p):                       # p = [m, c, ε] per body, ε = 0 at the file's values
        return si.from_physical(p[:, 0], p[:, 1:4], si.strained(d, R, p[:, 4:]))

    p0 = np.column_stack([m, c, np.zeros((len(m), 6))])
    for k in range(10):
        e = np.zeros(10)
        e[k] = 1e-6 * max(np.abs(p0[:, k]).max(), 1e-2)
        fd = ((theta_of(p0 + e) - theta_of(p0 - e)) / (2 * e[k])).reshape(-1, 10)
        np.testing.assert_allclose(J[:, :, k], fd, atol=1e-7 * np.abs(fd).max() + 1e-15)


def test_strain_keeps_every_draw_physical_and_is_isotropic(leg):
    """A large strain still gives Σ_c ⪰ 0; the strain's law does not depend on the principal
    frame, so a rotated body gets the rotated covariance."""
    th = leg.parameters()
    big = si.draw(th, leg.body_sizes_m, ModelUncertainty.uniform(0.6), np.random.default_rng(3), 500)
    g = np.array([leg.consistency_margins(x) for x in big]).reshape(len(big), -1, 6)
    assert np.all(g[:, :, 1:] >= 0)                         # I_c ⪰ 0 and the triangle, always
    unc = ModelUncertainty(mass_rel=0.05, inertia_rel=0.1, com_m=0.0)
    m, h, Io = si.unpack(th)
    from scipy.spatial.transform import Rotation

    Q = Rotation.from_rotvec([0.4, 0.2, -0.9]).as_matrix()
    rot = si.pack(m, h @ Q.T, Q @ Io @ Q.T)
    S = si.parameter_covariance(th, leg.body_sizes_m, unc)
    Sr = si.parameter_covariance(rot, leg.body_sizes_m, unc)
    for b in range(4):                      # I_o entries: Cov(Q δI Qᵀ) from Cov(δI)
        blk = slice(10 * b + 4, 10 * b + 10)
        L = np.zeros((6, 6))
        for k, (i, j) in enumerate(si._VECH):
            for l, (u, v) in enumerate(si._VECH):
                L[k, l] = Q[i, u] * Q[j, v] + (Q[i, v] * Q[j, u] if u != v else 0.0)
        np.testing.assert_allclose(Sr[blk, blk], L @ S[blk, blk] @ L.T, atol=1e-9 * np.abs(S[blk, blk]).max())


@pytest.mark.parametrize("which, unc", [
    ("leg", ModelUncertainty(mass_rel=0.02, inertia_rel=0.05, com_m=0.0002)),
    ("tree", ModelUncertainty.uniform(0.01)),
])
def test_covariance_matches_a_monte_carlo_of_the_physical_draws(which, unc, leg, tree):
    """Σ_θ = J Σ_p Jᵀ (linearized) against the sample covariance of θ over draws of the physical
    errors at a small σ; PSD with full rank 10 per body (mass, 3 COM, 6 strains). Entries are
    compared within 5 % (sampling) + 0.5 % of the largest σ of their body's group (m | m c | I_o):
    a σ the linearization sets to 0 (I_xy of a body with c_x = c_y = 0) is m σ_c² at second order."""
    model = leg if which == "leg" else tree
    th = model.parameters()
    S = model.parameter_covariance(unc)
    d = np.sqrt(np.diag(S))
    live = d > 0
    lam = np.linalg.eigvalsh(S[np.ix_(live, live)] / np.outer(d[live], d[live]))   # units differ
    assert lam.min() > -1e-12
    assert np.sum(lam > 1e-9) == 10 * len(model.tree.body_names)
    draws = si.draw(th, model.body_sizes_m, unc, np.random.default_rng(2), 8000)
    groups = np.tile(np.r_[0, 1, 1, 1, [2] * 6], len(d) // 10) + 3 * np.repeat(np.arange(len(d) // 10), 10)
    gmax = np.array([d[groups == g].max() for g in groups])
    assert np.all(np.abs(draws.std(axis=0) - d) < 0.05 * d + 0.005 * gmax)
    s = d + 0.1 * gmax
    emp = np.cov(draws.T)
    assert np.all(np.abs(emp - S) / np.outer(s, s) < 0.06)
    assert not [1 for x in draws[:200] if model.consistency_problems(x)]


def test_com_sigma_relative_to_the_body_size(leg):
    """``relative`` scales the COM σ by each body's size ℓ (segment to its farthest child joint)."""
    np.testing.assert_allclose(leg.body_sizes_m, [np.hypot(0.06, 0.04), 0.07, 0.2, 0.2])
    S = leg.parameter_covariance(ModelUncertainty(mass_rel=0.0, inertia_rel=0.0, com_m=None,
                                                  relative=0.1))
    m = leg.parameters()[::10]
    for b in range(4):                       # Var(mc_x) = (m σ_c)² with the mass exact
        assert S[10 * b + 1, 10 * b + 1] == pytest.approx((m[b] * 0.1 * leg.body_sizes_m[b]) ** 2)


def test_perturbed_robot_is_one_draw(leg):
    unc = ModelUncertainty.uniform(0.1)
    p = leg.perturbed(unc, seed=7)
    expect = si.draw(leg.parameters(), leg.body_sizes_m, unc, np.random.default_rng(7))
    np.testing.assert_allclose(p.parameters(), expect, rtol=1e-12, atol=1e-15)
    assert p.consistency_problems(p.parameters()) == []
    assert p.name == "quadruped_leg_perturbed_7" and p.robot.model_uncertainty is None
    assert p.joint_names == leg.joint_names and np.allclose(p.tree.pp, leg.tree.pp)
    assert not np.allclose(p.parameters(), leg.parameters())


def _decl(tmp_path, extra: str):
    shutil.copy("robots/quadruped_leg.urdf", tmp_path / "quadruped_leg.urdf")
    text = open(LEG).read() + "\n" + extra
    (tmp_path / "leg.toml").write_text(text)
    return tmp_path / "leg.toml"


def _toml_matrix(C):
    return "[" + ", ".join("[" + ", ".join(f"{x:.17g}" for x in row) + "]" for row in C) + "]"


def test_declared_uncertainty_and_identification_tables(tmp_path, leg):
    assert leg.model_covariance() == (None, "the robot file is not identified and declares no "
                                            "[model_uncertainty]")
    model = UrdfModel(load_spatial_robot(_decl(tmp_path, "[model_uncertainty]\nrelative = 0.05\n")))
    cov, source = model.model_covariance()
    np.testing.assert_allclose(cov, leg.parameter_covariance(ModelUncertainty.uniform(0.05)))
    assert source.startswith("declared model uncertainty: masses ±5 %")

    names = "[" + ", ".join(f'"{n}"' for n in leg.parameter_names) + "]"
    th = "[" + ", ".join(f"{x:.17g}" for x in leg.parameters()) + "]"
    C = np.eye(40) * 1e-8
    ident = (f"[identification]\nparameter_names = {names}\nparameters = {th}\n"
             f"covariance = {_toml_matrix(C)}\n[[identification.logs]]\npath = \"run.csv\"\n")
    model = UrdfModel(load_spatial_robot(_decl(tmp_path, "[model_uncertainty]\nrelative = 0.05\n" + ident)))
    cov, source = model.model_covariance()
    np.testing.assert_allclose(cov, C)
    assert source == "identification of quadruped_leg from run.csv"


@pytest.mark.parametrize("table, message", [
    ("[model_uncertainty]\nrelative = 2.0\n", "model_uncertainty.relative: 2 is outside the physical range [0, 1]"),
    ("[model_uncertainty]\nmass_rel = 0.05\n", "model_uncertainty.inertia_rel: missing field"),
    ("[model_uncertainty]\nrealtive = 0.05\n", "model_uncertainty.realtive: unknown field (did you mean 'relative'?)"),
    ("[identification]\nparameter_names = [\"a\"]\nparameters = [1.0]\ncovariance = [[1.0]]\n",
     "identification.parameter_names: expected ['base.m'"),
    ("IDENT_EDITED", "identification.parameters: hip.m = 0.5 differs from the file's inertial data"),
    ("IDENT_BADCOV", "identification.covariance: must be symmetric positive semi-definite"),
])
def test_bad_tables_are_named(tmp_path, leg, table, message):
    names = "[" + ", ".join(f'"{n}"' for n in leg.parameter_names) + "]"
    th = leg.parameters()
    if table.startswith("IDENT"):
        C = np.eye(40) * 1e-8
        if table == "IDENT_EDITED":
            th = th.copy()
            th[10] = 0.5
        else:
            C[0, 0] = -1.0
        table = (f"[identification]\nparameter_names = {names}\nparameters = "
                 f"[{', '.join(f'{x:.17g}' for x in th)}]\ncovariance = {_toml_matrix(C)}\n")
    path = _decl(tmp_path, table)
    with pytest.raises(InputError, match=re.escape(message)) as exc:
        load_spatial_robot(path)
    assert str(path) in str(exc.value) and "\n" not in str(exc.value)


def test_written_robot_reads_back_with_its_identification(tmp_path, leg):
    """A URDF robot with other inertial parameters written (URDF + declaration TOML with an
    [identification] table) reads back with those parameters; the fixed foot merges as before."""
    from estimator.spatial.write import declaration_toml, urdf_with_parameters
    from userio.files import read_toml

    other = leg.perturbed(ModelUncertainty.uniform(0.1), seed=4)
    th = other.parameters()
    (tmp_path / "leg_id.urdf").write_text(urdf_with_parameters(leg, th))
    C = np.diag((0.01 * np.abs(th) + 1e-9) ** 2)
    table = {"parameter_names": list(leg.parameter_names), "parameters": th, "covariance": C,
             "logs": [{"path": "run.csv", "sha256": "00"}], "statistics": {"chi2_per_dof": 1.0}}
    decl = read_toml(LEG)
    decl["model_uncertainty"] = {"relative": 0.05}
    (tmp_path / "leg_id.toml").write_text(declaration_toml(decl, "leg_id.urdf", "leg_id", tmp_path, table,
                                                           "# identified"))
    back = UrdfModel(load_spatial_robot(tmp_path / "leg_id.toml"))
    np.testing.assert_allclose(back.parameters(), th, rtol=1e-10, atol=1e-14)
    assert back.tree.body_names == leg.tree.body_names and back.joint_names == leg.joint_names
    assert back.robot.ft_frame == "ft_sensor" and back.robot.model_uncertainty is None
    np.testing.assert_allclose(back.robot.mount_stiffness, leg.robot.mount_stiffness)
    cov, source = back.model_covariance()
    np.testing.assert_allclose(cov, C)
    assert source == "identification of leg_id from run.csv"
