"""A published quadruped (Solo-12 from the example-robot-data package: 12 joints, four legs,
collision meshes in STL reached through package:// URIs) through the URDF path: the compiled
terms against pinocchio, and contacts on its concave leg meshes either located exactly on the
right link or refused with a reason (a line that enters a concave mesh twice)."""

from __future__ import annotations

import sysconfig
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("pinocchio")

from estimator.spatial import localize as loc  # noqa: E402
from estimator.spatial.geometry import body_surfaces  # noqa: E402
from estimator.spatial.model import UrdfModel, columns, moves, pinocchio_terms  # noqa: E402
from estimator.spatial.noise import default_noise, residual_covariance  # noqa: E402
from estimator.spatial.predict import solid_mesh  # noqa: E402
from estimator.spatial.robot import robot_from_urdf  # noqa: E402
from estimator.spatial.tree import body_poses  # noqa: E402
from tests.spatial_urdf import random_states  # noqa: E402

SOLO = (Path(sysconfig.get_paths()["purelib"]) / "cmeel.prefix" / "share" / "example-robot-data"
        / "robots" / "solo_description" / "robots" / "solo12.urdf")
pytestmark = pytest.mark.skipif(not SOLO.is_file(), reason="example-robot-data is not installed")


@pytest.fixture(scope="module")
def solo():
    return UrdfModel(robot_from_urdf(SOLO))


def test_solo12_terms_match_pinocchio(solo):
    assert len(solo.joint_names) == 12 and solo.tree.n_bodies == 13
    q, v, tau = random_states(np.random.default_rng(0), 10, 12)
    P, u = solo.momentum_terms(q, v, tau)
    P2, u2 = pinocchio_terms(solo.robot, q, v, tau)
    assert np.abs(P - P2).max() < 1e-12 * np.abs(P2).max() and np.abs(u - u2).max() < 1e-12 * np.abs(u2).max()


def test_solo12_contacts_on_concave_leg_meshes(solo):
    surfs = body_surfaces(solo.robot, solo.tree)
    q = solo.robot.rest_q()
    q[7:] = np.tile([0.0, 0.8, -1.6], 4)
    R = residual_covariance(solo, q[None], np.zeros((1, solo.n_v)), default_noise(solo), 100.0, 1e-3)[0]
    L = np.linalg.inv(np.linalg.cholesky(R))
    S, *_ = columns(solo.tree, q[None])
    Rb, pb, _, _ = body_poses(solo.tree, q[None], relative=True)
    rng = np.random.default_rng(1)
    for name in ("FL_LOWER_LEG", "HL_UPPER_LEG"):
        b = solo.tree.body_names.index(name)
        link, shape = surfs[b].solids[0]
        mesh = solid_mesh(shape)
        idx = rng.choice(len(mesh.faces), 30, replace=False)
        V, N = mesh.triangles_center[idx], mesh.face_normals[idx]
        pw = pb[0, b] + V @ Rb[0, b].T
        F = -5.0 * (N @ Rb[0, b].T)
        r = (np.c_[F, np.cross(pw, F)] @ S[0].T) * moves(solo.tree)[:, b]
        res = loc.localize(solo, surfs, np.tile(q, (30, 1)), r, L)
        ok = res.reason == loc.OK
        names, counts = np.unique(np.asarray(loc.REASONS)[res.reason[~ok]], return_counts=True)
        print(f"{name}: {ok.sum()} of 30 located; refused: {dict(zip(names.tolist(), counts.tolist()))}")
        assert ok.mean() >= 0.4
        assert (res.link[ok] == link).all()
        assert np.abs(res.point_body[ok] - V[ok]).max() < 1e-9
        assert set(res.reason[~ok]) <= {loc.SEVERAL, loc.AMBIGUOUS, loc.GRAZING}
