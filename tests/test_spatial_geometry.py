"""Lines of action entering collision solids: the entry point lies on the surface (outside just
before, inside just after), the normal is unit and opposes the direction; a miss never touches."""

from __future__ import annotations

import numpy as np
import pytest

from estimator.spatial.geometry import entry
from estimator.spatial.robot import Shape, rpy_matrix


def _inside(kind, size, x):
    if kind == "cylinder":
        return (x[:, 0] ** 2 + x[:, 1] ** 2 <= size[0] ** 2) & (np.abs(x[:, 2]) <= size[1] / 2)
    if kind == "box":
        return np.all(np.abs(x) <= np.array(size) / 2, axis=1)
    if kind == "sphere":
        return np.linalg.norm(x, axis=1) <= size[0]
    zc = np.clip(x[:, 2], -size[1] / 2, size[1] / 2)
    return np.hypot(x[:, 0], x[:, 1]) ** 2 + (x[:, 2] - zc) ** 2 <= size[0] ** 2


@pytest.mark.parametrize("kind, size", [("cylinder", (0.03, 0.2)), ("box", (0.1, 0.2, 0.05)),
                                        ("sphere", (0.04,)), ("capsule", (0.02, 0.1)), ("mesh", None)])
def test_entry_points(kind, size, tmp_path):
    rng = np.random.default_rng(0)
    R, c = rpy_matrix([0.3, -0.7, 1.1]), np.array([0.01, -0.02, 0.03])
    if kind == "mesh":                      # a box as an STL, scaled ×2 by the URDF
        import trimesh

        path = tmp_path / "box.stl"
        trimesh.creation.box(extents=(0.05, 0.1, 0.025)).export(path)
        shape, local = Shape("mesh", (2.0, 2.0, 2.0), R, c, str(path)), ("box", (0.1, 0.2, 0.05))
    else:
        shape, local = Shape(kind, size, R, c), (kind, size)
    o = rng.normal(size=(1500, 3)) * 0.1
    d = rng.normal(size=(1500, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    s, n = entry(shape, o, d)
    hit = np.isfinite(s)
    assert 0.05 < hit.mean() < 0.6
    to_local = lambda x: (x - c) @ R  # noqa: E731
    p = o[hit] + s[hit, None] * d[hit]
    assert not _inside(*local, to_local(p - 1e-7 * d[hit])).any()
    assert _inside(*local, to_local(p + 1e-7 * d[hit])).all()
    assert np.allclose(np.linalg.norm(n[hit], axis=1), 1.0)
    assert (np.einsum("si,si->s", n[hit], d[hit]) < 0).all()
    grid = np.linspace(-1, 1, 2001)
    for i in np.flatnonzero(~hit)[:100]:
        assert not _inside(*local, to_local(o[i] + grid[:, None] * d[i])).any()
