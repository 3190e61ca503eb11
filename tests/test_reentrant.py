"""Sharp re-entrant edges from a mesh's boundary (flexure.reentrant): the interior dihedral angle."""

import numpy as np
import pytest

from flexure.mesh import Mesh, box_mesh, cylinder_mesh
from flexure.reentrant import has_sharp_reentrant_edge, max_interior_angle_deg


def test_a_box_has_no_concave_edge():
    assert max_interior_angle_deg(box_mesh(3, 2, 2)) == pytest.approx(180.0)
    assert not has_sharp_reentrant_edge(box_mesh(3, 2, 2))


def test_an_l_shape_has_a_270_degree_edge():
    """A 2 × 2 × 1 block without one quarter: the inner corner's edge is re-entrant at 270°."""
    m = box_mesh(4, 4, 2, size=(2.0, 2.0, 1.0))
    c = m.points[m.tets].mean(axis=1)
    keep = ~((c[:, 0] > 1.0) & (c[:, 1] > 1.0))
    used = np.unique(m.tets[keep])
    remap = np.full(m.n_nodes, -1)
    remap[used] = np.arange(len(used))
    lm = Mesh(m.points[used], remap[m.tets[keep]])
    assert max_interior_angle_deg(lm) == pytest.approx(270.0)
    assert has_sharp_reentrant_edge(lm)


@pytest.mark.parametrize("n_theta, omega", [(12, 210.0), (48, 187.5)])
def test_a_faceted_bore_is_concave_but_not_sharp(n_theta, omega):
    """An annulus's bore, a polygon of n sides, turns 360°/n per edge: ω = 180° + 360°/n, below SHARP_DEG."""
    m = cylinder_mesh(0.3, 1.0, 0.5, 2, n_theta, 1)
    assert max_interior_angle_deg(m) == pytest.approx(omega, abs=1e-6)
    assert not has_sharp_reentrant_edge(m)
