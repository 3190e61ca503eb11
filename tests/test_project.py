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


@pytest.mark.parametrize("on", [True, False])
def test_closest_on_candidates_is_the_nearest_of_each_rows_triangles(on, monkeypatch):
    """flexure.closest, compiled or not (trimesh's row width by row width): each point's closest point
    on its candidates (rows of 1–5 triangles) is the nearest of trimesh's per triangle, and the
    one-triangle form (the gauge check's) is trimesh's itself."""
    from trimesh.triangles import closest_point

    from estimator import compiled
    from flexure.closest import closest_on_candidates, closest_points

    monkeypatch.setattr(compiled, "ENABLED", on)
    rng = np.random.default_rng(11)
    tri = rng.normal(size=(200, 3, 3))
    pts = rng.normal(size=(60, 3)) * rng.choice([0.1, 1.0, 10.0], size=(60, 1))
    width = rng.integers(1, 6, size=60)
    indptr = np.r_[0, np.cumsum(width)]
    indices = rng.integers(0, 200, size=indptr[-1])
    cp, d = closest_on_candidates(pts, tri, indptr, indices)
    for i in range(60):
        cand = indices[indptr[i]:indptr[i + 1]]
        q = closest_point(tri[cand], np.repeat(pts[i:i + 1], len(cand), axis=0))
        dist = np.linalg.norm(q - pts[i], axis=1)
        assert np.isclose(d[i], dist.min(), rtol=1e-12, atol=1e-12)
        assert np.allclose(cp[i], q[dist.argmin()], rtol=0, atol=1e-9)
    assert np.allclose(closest_points(tri[:60], pts), closest_point(tri[:60], pts), rtol=0, atol=1e-12)


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


def test_samples_cover_needles_and_small_facets_within_their_gap():
    """Every point of a triangle is within ``gap`` of one of its own samples (project.samples: the
    ball query's certificate rests on it): random points in needles 50 long and 0.05 wide, in facets
    far below the spacing and in ordinary ones; a needle gets a few samples across, not a grid."""
    from scipy.spatial import cKDTree

    from flexure.project import samples

    rng = np.random.default_rng(11)
    needles = np.array([[[0, 0, 0], [50, 0.05, 0], [49.5, -0.02, 0.01]]], float) + rng.normal(size=(40, 1, 3))
    tiny = rng.normal(size=(40, 1, 3)) + 0.01 * rng.normal(size=(40, 3, 3))
    plain = rng.normal(size=(40, 1, 3)) * 10 + rng.normal(size=(40, 3, 3)) * 2
    tri = np.concatenate([needles, tiny, plain])
    pts, owner, gap = samples(tri, 0.3)
    assert gap <= 0.3 * 1.5 + 1e-12
    w = rng.dirichlet(np.ones(3), size=(len(tri), 200))
    x = np.einsum("tsa,tai->tsi", w, tri)
    worst = max(cKDTree(pts[owner == t]).query(x[t])[0].max() for t in range(len(tri)))
    assert worst <= gap
    per = np.bincount(owner, minlength=len(tri))
    assert per[:40].max() < 4 * (50 / 0.3 + 1) and per[40:80].max() == 3      # rows of 2–3, corners only


def test_projection_on_an_extruded_needle_stl_equals_brute_force():
    """A disc with bolt holes extruded the way trimesh's docs show (earcut caps of needle facets,
    small facets on the holes' walls): the certified projection is the closest point over every facet."""
    import trimesh
    from shapely.geometry import Point

    from flexure.geometry import Surface
    from flexure.project import StlProjector

    poly = Point(0, 0).buffer(26, 64).difference(Point(0, 0).buffer(20, 64))
    for k in range(6):
        poly = poly.difference(Point(23 * np.cos(k), 23 * np.sin(k)).buffer(0.8, 12))
    m = trimesh.creation.extrude_polygon(poly, 5.0)
    tri = np.asarray(m.vertices)[m.faces] * 1e-3
    proj = StlProjector(Surface(np.asarray(m.vertices) * 1e-3, np.asarray(m.faces)))
    rng = np.random.default_rng(4)
    pts = tri[rng.integers(len(tri), size=300)].mean(axis=1) + rng.normal(scale=4e-4, size=(300, 3))
    # brute force in mm: trimesh's closest point has absolute tolerances that miss by µm in metres
    brute = 1e-3 * np.array([np.linalg.norm(trimesh.triangles.closest_point(tri * 1e3, np.repeat(p[None] * 1e3, len(tri), 0))
                                            - p * 1e3, axis=1).min() for p in pts])
    got = np.linalg.norm(proj.project(pts) - pts, axis=1)
    assert got == pytest.approx(brute, rel=1e-9, abs=1e-15)
