"""What the size field resolves besides the gauges, and boundary sets on curved faces: the sharp
re-entrant edges of a part (flexure.meshing.reentrant_edges), and P2 mid-edge nodes of a clamped
convex face (flexure.analysis._selections)."""

from pathlib import Path

import numpy as np
import shapely.geometry

from flexure.analysis import _selections, build_mesh
from flexure.design import load_design
from flexure.geometry import extrude
from flexure.mesh import to_quadratic
from flexure.meshing import reentrant_edges
import pytest

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


@pytest.mark.parametrize("stl", ["fem_reference/thick_disc.stl", "fem_unseen/six_spoke_thick.stl",
                                 "fem_unseen/held_out/five_needle.stl"])
def test_reentrant_edges_are_trimeshs_concave_folds(stl):
    """The sharp re-entrant edges from our fold angles (flexure.reentrant.fold_angles_deg: ω > 180° +
    40°) are exactly the concave face adjacencies trimesh finds folded by more than 40°, on STLs of
    thick, needle-spoked and bolted discs (a second implementation's answer)."""
    import trimesh

    from flexure.meshing import EDGE_ANGLE_DEG
    from flexure.reentrant import fold_angles_deg

    m = trimesh.load(DATA.parent / stl, process=True)
    sharp = (m.face_adjacency_angles > np.deg2rad(EDGE_ANGLE_DEG)) & ~m.face_adjacency_convex
    theirs = {tuple(sorted(e)) for e in m.face_adjacency_edges[sharp].tolist()}
    edges, omega = fold_angles_deg(m.vertices, m.faces)
    ours = {tuple(e) for e in edges[omega > 180.0 + EDGE_ANGLE_DEG].tolist()}
    assert len(ours) >= 8 and ours == theirs


def test_p2_mid_edge_nodes_of_a_clamped_outer_face_are_clamped():
    """The STEP part held at its outer face (r ≥ 24.975 mm of a 25 mm rim) on a coarse level
    (h × 2): every node of every boundary face whose vertices are clamped is clamped, though a
    straight mid-edge node of a long chord sits more than the 25 µm tolerance inside the rim."""
    design = load_design(DATA / "step_part.toml")
    mesh = to_quadratic(build_mesh(design, order=1, h_factor=2.0).mesh)     # straight-sided P2
    _, fixed = _selections(design, mesh)
    is_fixed = np.zeros(mesh.n_nodes, bool)
    is_fixed[fixed] = True
    faces = mesh.boundary_faces()                                 # (k, 6): corners, then mid-edge nodes
    on_rim = faces[is_fixed[faces[:, :3]].all(axis=1)]
    assert len(on_rim) > 20
    r = np.hypot(*mesh.points[on_rim[:, 3:].ravel(), :2].T)
    assert r.min() < 0.025 - 25e-6                                # some lie outside the old test
    assert is_fixed[on_rim[:, 3:]].all()


def test_p2_on_a_cad_solid_puts_mid_edge_nodes_on_its_curved_faces():
    """gmsh's second-order nodes (isoparametric P2) on the exact solid: the mid-edge nodes of the
    rim's and the bore's boundary edges lie on r = 25 mm and 3 mm (not on the chords), every
    element's Jacobian is positive at its quadrature points and nodes, and the clamped rim's
    mid-edge nodes are clamped. On the coarsest default level (h × √2); at h × 2 the bore's chords
    span up to 50° and 15 of its 84 mid-edge nodes are put back on them to keep the Jacobian
    positive (gmsh_mesh._curved_quadratic)."""
    from flexure.fem import TET_QUAD, tet_shape
    from flexure.gmsh_mesh import MIN_SCALED_JACOBIAN
    from flexure.post import REF_NODES

    design = load_design(DATA / "step_part.toml")
    mesh = build_mesh(design, order=2, h_factor=2.0 ** 0.5).mesh
    load, fixed = _selections(design, mesh)
    faces = mesh.boundary_faces()
    for nodes, radius in ((fixed, 0.025), (load, 0.003)):
        chosen = np.zeros(mesh.n_nodes, bool)
        chosen[nodes] = True
        mids = faces[chosen[faces[:, :3]].all(axis=1)][:, 3:].ravel()
        r = np.hypot(*mesh.points[mids, :2].T)
        assert len(mids) > 20 and chosen[mids].all()
        np.testing.assert_allclose(r, radius, rtol=1e-6)
    _, dN = tet_shape(2, np.vstack([TET_QUAD[2][0], REF_NODES]))
    X = mesh.points[mesh.tets]
    J = np.einsum("eai,qak->eqik", X, dN)
    affine = np.linalg.det(X[:, 1:4] - X[:, :1])[:, None]
    assert (np.linalg.det(J) >= MIN_SCALED_JACOBIAN * affine).all()


@pytest.mark.slow
def test_curved_elements_do_not_make_stress_spikes(monkeypatch):
    """Nearly folded curved elements (det J ≪ its straight value at a node) read spurious nodal
    strains: the paper disc's peak von Mises was 965 MPa at h × √2 with any positive det J allowed,
    against 60.6 MPa on the straight mesh. With MIN_SCALED_JACOBIAN the peak stays near the
    straight mesh's (64.3, 63.9 MPa against 60.6, 65.4 at h × √2, 1; tested to 15 %)."""
    from flexure.analysis import analyze

    from flexure import gmsh_mesh

    design = load_design(DATA.parents[2] / "designs" / "paper_disc.toml")
    curved = [analyze(design, h_factor=h)[0]["max_von_mises_Pa"] for h in (2.0 ** 0.5, 1.0)]

    def straight_only(*args):
        raise RuntimeError("straight P2")          # _session falls back to mid-edge nodes on the chords

    monkeypatch.setattr(gmsh_mesh, "_geometric_midpoints", straight_only)
    straight = [analyze(design, h_factor=h)[0]["max_von_mises_Pa"] for h in (2.0 ** 0.5, 1.0)]
    np.testing.assert_allclose(curved, straight, rtol=0.15)


@pytest.mark.slow
def test_a_tetrahedron_below_10_degrees_sends_the_mesher_back_finer_around_it(monkeypatch):
    """The re-entrant part at its answer level (h × 1/√2): gmsh's first volume mesh has a 9.7°
    tetrahedron at the rim (all four nodes on the plate's faces, which no optimiser moves); the
    second pass, finer around it, has none below 10° for about 1 % more elements."""
    from flexure import gmsh_mesh
    from flexure.mesh import element_shape_metrics, quality

    passes = []
    one_pass = gmsh_mesh._one_pass

    def spy(*args):
        points, tets, geometric, entities = one_pass(*args)
        passes.append((len(tets), element_shape_metrics(points, tets)["dihedral_deg"].min()))
        return points, tets, geometric, entities

    monkeypatch.setattr(gmsh_mesh, "_one_pass", spy)
    mesh = build_mesh(load_design(DATA / "reentrant.toml"), order=1, h_factor=2 ** -0.5).mesh
    assert len(passes) >= 2 and passes[0][1] < gmsh_mesh.MIN_DIHEDRAL_DEG
    assert quality(mesh)["min_dihedral_deg"] >= gmsh_mesh.MIN_DIHEDRAL_DEG
    assert mesh.n_elements < 1.05 * passes[0][0]
