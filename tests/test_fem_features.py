"""What the size field resolves besides the gauges, and boundary sets on curved faces: the sharp
re-entrant edges of a part (flexure.meshing.reentrant_edges), and P2 mid-edge nodes of a clamped
convex face (flexure.analysis._selections)."""

from pathlib import Path

import numpy as np
import shapely.geometry

from flexure.analysis import _selections, build_mesh
from flexure.design import load_design
from flexure.geometry import extrude
from flexure.meshing import reentrant_edges

DATA = Path(__file__).resolve().parent / "data" / "fem_reference"


def test_an_l_shaped_block_has_one_reentrant_edge_and_a_box_none():
    """An L (10 × 10 mm with a 5 × 5 mm notch) extruded 2 mm: the notch's inner corner is the one
    re-entrant edge, from z = 0 to z = 2 mm; its convex corners and a plain box give none."""
    ell = shapely.geometry.Polygon([(0, 0), (10, 0), (10, 5), (5, 5), (5, 10), (0, 10)])
    edges = reentrant_edges(extrude(shapely.affinity.scale(ell, 1e-3, 1e-3, origin=(0, 0)), 2e-3))
    assert len(edges) >= 1
    assert np.allclose(edges[..., :2], 5e-3)                      # all on the notch's corner line
    z = np.sort(edges[..., 2].ravel())
    assert z[0] == 0.0 and np.isclose(z[-1], 2e-3)
    box = shapely.geometry.box(0, 0, 10e-3, 10e-3)
    assert len(reentrant_edges(extrude(box, 2e-3))) == 0


def test_p2_mid_edge_nodes_of_a_clamped_outer_face_are_clamped():
    """The STEP part held at its outer face (r ≥ 24.975 mm of a 25 mm rim) on a coarse level
    (h × 2): every node of every boundary face whose vertices are clamped is clamped, though a
    straight mid-edge node of a long chord sits more than the 25 µm tolerance inside the rim."""
    design = load_design(DATA / "step_part.toml")
    mesh = build_mesh(design, order=2, h_factor=2.0).mesh
    _, fixed = _selections(design, mesh)
    is_fixed = np.zeros(mesh.n_nodes, bool)
    is_fixed[fixed] = True
    faces = mesh.boundary_faces()                                 # (k, 6): corners, then mid-edge nodes
    on_rim = faces[is_fixed[faces[:, :3]].all(axis=1)]
    assert len(on_rim) > 20
    r = np.hypot(*mesh.points[on_rim[:, 3:].ravel(), :2].T)
    assert r.min() < 0.025 - 25e-6                                # some lie outside the old test
    assert is_fixed[on_rim[:, 3:]].all()
