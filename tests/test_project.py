"""The STL projector's closest-point kernel (flexure._closest_kernels) against trimesh's, and its
certified ball search (every triangle that can hold a closer point is looked at)."""

import numpy as np
import pytest

pytest.importorskip("numba")


def test_closest_point_kernel_matches_trimesh_on_every_voronoi_region():
    """Points around random triangles (vertex, edge and face regions, both sides, far and near) and
    flat triangles (collinear corners: the nearest of their edges)."""
    from trimesh.triangles import closest_point

    from flexure._closest_kernels import closest_on_triangles

    rng = np.random.default_rng(7)
    tri = rng.normal(size=(300, 3, 3))
    tri[:20, 2] = tri[:20, 0] + 0.37 * (tri[:20, 1] - tri[:20, 0])   # flat: c on the segment ab
    pts = tri.mean(axis=1) + rng.normal(scale=2.0, size=(300, 3))
    cp, d = closest_on_triangles(pts, tri, np.arange(301), np.arange(300))
    ref = closest_point(tri, pts)
    assert np.abs(cp - ref).max() < 1e-9
    assert np.allclose(d, np.linalg.norm(ref - pts, axis=1), rtol=1e-12, atol=1e-12)


def test_certified_projection_equals_brute_force_with_and_without_numba():
    """Points near a coarse facetted cylinder (long thin facets: the nearest samples often belong to
    a farther facet, so the certifying ball search decides) go to the brute-force closest point over
    every facet, compiled or not."""
    import trimesh

    from estimator import compiled
    from flexure.geometry import Surface
    from flexure.project import StlProjector

    cyl = trimesh.creation.cylinder(radius=0.01, height=0.03, sections=12)
    proj = StlProjector(Surface(np.asarray(cyl.vertices), np.asarray(cyl.faces)))
    rng = np.random.default_rng(3)
    pts = rng.uniform(-0.012, 0.012, size=(200, 3)) * [1, 1, 1.4]
    tri = np.asarray(cyl.vertices)[cyl.faces]
    brute = np.array([np.linalg.norm(trimesh.triangles.closest_point(tri, np.repeat(p[None], len(tri), 0)) - p,
                                     axis=1).min() for p in pts])
    was = compiled.ENABLED
    try:
        for on in (True, False):
            compiled.ENABLED = on
            got = np.linalg.norm(proj.project(pts) - pts, axis=1)
            assert got == pytest.approx(brute, rel=1e-9, abs=1e-15)
    finally:
        compiled.ENABLED = was


def test_compiled_element_validity_matches_the_numpy_check():
    """mesh_motion.element_valid compiled against its numpy form on a P2 box mesh whose mid nodes are
    pushed at random (some elements folded, some inverted straight), at two floors."""
    from estimator import compiled
    from flexure.mesh import box_mesh, to_quadratic
    from flexure.mesh_motion import element_valid

    mesh = to_quadratic(box_mesh(6, 6, 3, (0.01, 0.01, 0.004)))
    rng = np.random.default_rng(5)
    mids = np.unique(mesh.tets[:, 4:])
    mesh.points[mids] += rng.normal(scale=6e-4, size=(len(mids), 3))
    mesh.points[mesh.tets[:5, 0]] = mesh.points[mesh.tets[:5, 1]]            # flat straight corners
    el = rng.permutation(len(mesh.tets))[:300]
    was = compiled.ENABLED
    try:
        got = {}
        for on in (True, False):
            compiled.ENABLED = on
            got[on] = [element_valid(mesh, el, s) for s in (0.05, 0.25)] + [element_valid(mesh, np.arange(5), 0.05)]
    finally:
        compiled.ENABLED = was
    for a, b in zip(got[True], got[False]):
        assert np.array_equal(a, b)
    assert 0 < got[True][0].sum() < len(el) and not got[True][2].any()
