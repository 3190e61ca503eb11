"""The 3-D error map: first-order prediction against a Monte Carlo of the localizer, the
propagate command's map and the pictures."""

from __future__ import annotations

import json

import numpy as np
import pytest

pytest.importorskip("pinocchio")

from estimator.spatial import localize as loc  # noqa: E402
from estimator.spatial.geometry import body_surfaces  # noqa: E402
from estimator.spatial.model import UrdfModel, columns, moves  # noqa: E402
from estimator.spatial.noise import default_noise, residual_covariance  # noqa: E402
from estimator.spatial.predict import error_map  # noqa: E402
from estimator.spatial.robot import load_spatial_robot  # noqa: E402
from estimator.spatial.tree import body_poses  # noqa: E402


@pytest.fixture(scope="module")
def leg():
    return UrdfModel(load_spatial_robot("robots/quadruped_leg.toml"))


def test_first_order_map_matches_monte_carlo(leg):
    q = leg.robot.rest_q()
    q[7:] = [0.2, 0.6, -1.2]
    noise = default_noise(leg)
    maps = {m.link: m for m in error_map(leg, q, noise, 5.0, resolution=8)}
    surfaces = body_surfaces(leg.robot, leg.tree)
    R = residual_covariance(leg, q[None], np.zeros((1, 9)), noise, 100.0, 1e-3)[0]
    Linv = np.linalg.inv(np.linalg.cholesky(R))
    C = np.linalg.cholesky(R)
    S, *_ = columns(leg.tree, q[None])
    Rb, pb, _, _ = body_poses(leg.tree, q[None], relative=True)
    rng = np.random.default_rng(0)
    for link in ("thigh", "shank"):
        m = maps[link]
        from estimator.spatial.predict import solid_mesh, surface_samples

        shape = [s for nm, s in surfaces[m.body].solids if nm == link][0]
        normals = surface_samples(shape, solid_mesh(shape, 8))[1]     # the map's inward forces
        axis = shape.rotation[:, 2]
        # lateral points away from the rims (a rim's vertex normal is a corner's: there the
        # answer jumps between cap and side, and a first-order figure does not hold)
        lateral = (np.abs(normals @ axis) < 1e-6) & (np.abs((m.vertices - shape.origin) @ axis) < 0.35 * shape.size[1])
        for v in rng.choice(np.flatnonzero(np.isfinite(m.error_m) & lateral), 3, replace=False):
            b = m.body
            pw = pb[0, b] + Rb[0, b] @ m.vertices[v]
            n = normals[v]
            F = -5.0 * (Rb[0, b] @ n)
            r0 = S[0] @ np.r_[F, np.cross(pw, F)] * moves(leg.tree)[:, b]
            D = 4000
            r = np.tile(r0, (D, 1))
            r[:, :9] += rng.normal(size=(D, 9)) @ C.T
            res = loc.localize(leg, surfaces, np.tile(q, (D, 1)), r, Linv)
            ok = res.reason == loc.OK
            err = res.point_body[ok] - m.vertices[v]
            mc = np.sqrt((err ** 2).sum(axis=1).mean())
            print(f"{link} vertex {v}: first order {m.error_m[v] * 1e3:.3f} mm, Monte Carlo {mc * 1e3:.3f} mm")
            assert ok.mean() > 0.95
            assert abs(mc / m.error_m[v] - 1) < 0.2


def test_propagate_3d_map_and_picture(tmp_path, cli_inprocess):
    png = tmp_path / "map.png"
    res = cli_inprocess("propagate", "--robot", "robots/quadruped_leg.toml", "--posture", "0.2,0.6,-1.2",
                        "--force", "5", "--grid", "2", "--png", png, "--json")
    assert res.returncode == 0, res.stderr
    out = json.loads(res.stdout)
    assert set(out["links"]) == {"base", "hip", "thigh", "shank", "foot"}
    assert 1e-4 < out["links"]["shank"]["position_rms_median_m"] < 5e-3
    assert png.stat().st_size > 10000
    res = cli_inprocess("propagate", "--robot", "robots/quadruped_leg.toml", "--posture", "0.2,0.6")
    assert res.returncode == 2 and "--posture: expected 3 joint values" in res.stderr
