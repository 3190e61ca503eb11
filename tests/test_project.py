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
