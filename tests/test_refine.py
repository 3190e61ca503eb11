"""Nested local refinement (flexure.refine): longest-edge bisection with closure on P2 meshes,
exact prolongation, boundary nodes put back on the true geometry (flexure.project)."""

import numpy as np
import pytest

from flexure.mesh import box_mesh, cylinder_mesh, quality, to_quadratic
from flexure.refine import TaggedMesh, bisect, check_conforming, snap


def _quadratic(p):
    x, y, z = p.T
    return np.stack([x * x + y * z - 0.3 * z, y * y - x + 2 * x * z, z * x + 0.5 * y * y], axis=1)


def test_bisection_is_conforming_nested_and_prolongates_p2_exactly():
    """Random local marks over several steps: the mesh stays conforming (one mid node per edge,
    no hanging node, every interior face shared by two elements), the volume is unchanged (the
    children tile their parents), every marked element was split, and a P2 field (a quadratic)
    is carried over exactly."""
    rng = np.random.default_rng(3)
    tm = TaggedMesh.untagged(to_quadratic(box_mesh(3, 3, 4, size=(1.0, 0.8, 1.3))))
    u = _quadratic(tm.mesh.points)
    v0 = quality(tm.mesh)["total_volume_m3"]
    for _ in range(4):
        m = tm.mesh.n_elements
        marked = np.flatnonzero(rng.random(m) < 0.15)
        new, (u,), info = bisect(tm, marked, [u], rounds=2)
        check_conforming(new.mesh)
        assert new.mesh.n_elements >= m + 3 * len(marked)        # two rounds: ≥ 4 children each
        assert quality(new.mesh)["total_volume_m3"] == pytest.approx(v0, rel=1e-12)
        assert quality(new.mesh)["n_inverted"] == 0
        assert np.abs(u - _quadratic(new.mesh.points)).max() < 1e-12
        assert info["passes"] >= 2 and info["bisections"] >= 2 * len(marked)
        tm = new


def test_children_keep_face_tags_and_the_old_nodes():
    """Old nodes keep their numbers (a prolongated vector is the old one plus new entries); the
    boundary faces of the refined mesh all carry their parent's surface tag."""
    mesh = to_quadratic(box_mesh(2, 2, 2))
    tm = TaggedMesh.boundary_tagged(mesh, tag=7)
    new, _, _ = bisect(tm, np.arange(mesh.n_elements), [], rounds=3)
    assert np.array_equal(new.mesh.points[:mesh.n_nodes], mesh.points)
    from flexure.refine import _boundary_face_mask
    on_boundary = _boundary_face_mask(new.mesh)
    assert np.all(new.face_tag[on_boundary] == 7) and np.all(new.face_tag[~on_boundary] == 0)


class _Cylinder:
    """Projector onto the lateral surface r = R (tag 1) of a cylinder along z."""

    def __init__(self, R):
        self.R = R

    def project(self, points, dim, tag, certified=True):
        p = np.array(points, float)
        r = np.hypot(p[:, 0], p[:, 1])
        p[:, :2] *= (self.R / r)[:, None]
        return p


def test_new_boundary_nodes_go_onto_the_curved_surface():
    """A hollow cylinder meshed with straight P2 (mid nodes on the chords); snapping and
    refinement with the projector put every mid node and every new node of the outer face on
    r = R, with no element folded."""
    R = 1.0
    mesh = cylinder_mesh(0.5, R, 0.4, 2, 12, 2, order=1)
    mesh = to_quadratic(mesh)
    tm = TaggedMesh.untagged(mesh)
    from flexure.refine import _boundary_face_mask
    from flexure.mesh import TET_FACES
    bf = _boundary_face_mask(mesh)
    outer = np.hypot(*mesh.points[mesh.corner_tets][:, :, :2].transpose(2, 0, 1))[:, TET_FACES].min(axis=2) > R - 1e-9
    tm.face_tag[bf & outer] = 1
    proj = _Cylinder(R)
    snap(tm, proj)
    for _ in range(2):
        c = tm.mesh.points[tm.mesh.corner_tets].mean(axis=1)
        tm, _, info = bisect(tm, np.flatnonzero(c[:, 0] > 0.2), [], rounds=2, projector=proj)
        check_conforming(tm.mesh)
    faces = tm.mesh.boundary_faces()
    p = tm.mesh.points
    r = np.hypot(p[:, 0], p[:, 1])
    on_outer = faces[(r[faces[:, :3]] > R - 1e-9).all(axis=1)]
    assert len(on_outer) > 0
    assert np.abs(r[np.unique(on_outer)] - R).max() < 1e-12
    assert quality(tm.mesh)["n_inverted"] == 0 and len(tm.pending[0]) == 0


def test_gmsh_projector_on_a_cad_cylinder():
    """CadProjector: points near the lateral face of an OpenCASCADE cylinder (built in a gmsh
    session, mm) land on it; points near an edge curve land on the circle."""
    from flexure.project import CadProjector

    def build(gmsh):
        gmsh.model.occ.addCylinder(0, 0, 0, 0, 0, 5.0, 2.0)
        gmsh.model.occ.synchronize()

    proj = CadProjector(build)
    import gmsh
    rng = np.random.default_rng(0)
    first = proj.project(np.array([[2.1e-3, 0.0, 2.5e-3]]), np.array([2]), np.array([1]))
    assert proj._open and gmsh.isInitialized()             # the model is kept for the next call
    proj.close()
    assert not gmsh.isInitialized() and np.isfinite(first).all()
    a = rng.uniform(0, 2 * np.pi, 20)
    z = rng.uniform(0.5e-3, 4.5e-3, 20)
    pts = np.column_stack([2.1e-3 * np.cos(a), 2.1e-3 * np.sin(a), z])
    gmsh.initialize(interruptible=False)     # gmsh's default leaves SIGINT at SIG_DFL after finalize
    try:
        build(gmsh)
        lateral = [t for _, t in gmsh.model.getEntities(2)
                   if abs(gmsh.model.getBoundingBox(2, t)[5] - gmsh.model.getBoundingBox(2, t)[2]) > 1.0]
        circles = [t for _, t in gmsh.model.getEntities(1)]
    finally:
        gmsh.finalize()
    out = proj.project(pts, np.full(20, 2), np.full(20, lateral[0]))
    assert np.abs(np.hypot(out[:, 0], out[:, 1]) - 2e-3).max() < 1e-9
    assert np.allclose(out[:, 2], z)
    edge = np.column_stack([1.9e-3 * np.cos(a), 1.9e-3 * np.sin(a), np.full(20, 0.1e-3)])
    bottom = [c for c in circles if proj.project(edge[:1], np.array([1]), np.array([c]))[0, 2] < 1e-9]
    out = proj.project(edge, np.full(20, 1), np.full(20, bottom[0]))
    proj.close()
    assert np.abs(np.hypot(out[:, 0], out[:, 1]) - 2e-3).max() < 1e-9 and np.abs(out[:, 2]).max() < 1e-9


def test_stl_projector_finds_the_closest_triangle_point():
    """StlProjector against a brute-force closest point over every triangle of an icosphere."""
    import trimesh
    from trimesh.triangles import closest_point

    from flexure.geometry import Surface
    from flexure.project import StlProjector

    ico = trimesh.creation.icosphere(2, radius=0.01)
    proj = StlProjector(Surface(np.asarray(ico.vertices), np.asarray(ico.faces)))
    rng = np.random.default_rng(1)
    d = rng.normal(size=(40, 3))
    pts = 0.0101 * d / np.linalg.norm(d, axis=1, keepdims=True)
    got = proj.project(pts)
    tri = ico.vertices[ico.faces]
    for p, g in zip(pts, got):
        best = closest_point(tri, np.repeat(p[None], len(tri), axis=0))
        dist = np.linalg.norm(best - p, axis=1).min()
        assert np.linalg.norm(g - p) == pytest.approx(dist, rel=1e-9, abs=1e-15)


def test_stl_sharp_edges_are_curves_and_project_onto_the_stl_edges():
    """An STL box meshed: the mesh edges along the box's 12 edges (and only those) are tagged as
    curves (project.stl_tagged), and a point near an edge goes onto that edge (dim 1), not onto
    the nearer face (dim 2)."""
    import trimesh

    from flexure.geometry import Surface
    from flexure.mesh import TET_EDGES
    from flexure.project import StlProjector, stl_tagged

    box = trimesh.creation.box((0.02, 0.01, 0.006))
    proj = StlProjector(Surface(np.asarray(box.vertices), np.asarray(box.faces)))
    mesh = to_quadratic(box_mesh(4, 3, 2, size=(0.02, 0.01, 0.006)))
    mesh.points[:] -= np.array([0.01, 0.005, 0.003])
    tm = stl_tagged(mesh, proj)
    e, j = np.nonzero(tm.edge_tag > 0)
    a, b = mesh.points[mesh.tets[e, TET_EDGES[j, 0]]], mesh.points[mesh.tets[e, TET_EDGES[j, 1]]]
    half = np.array([0.01, 0.005, 0.003])
    on_two = lambda x: (np.isclose(np.abs(x), half).sum(axis=1) >= 2)  # noqa: E731 (on a box edge)
    assert len(e) and on_two(a).all() and on_two(b).all()
    n_edges = len(np.unique(np.sort(np.stack([mesh.tets[e, TET_EDGES[j, 0]], mesh.tets[e, TET_EDGES[j, 1]]], 1), 1), axis=0))
    assert n_edges == 4 * 4 + 4 * 3 + 4 * 2                                 # the box's edges, split 4, 3, 2 ways
    p = np.array([[0.004, 0.0049, 0.0029], [0.004, 0.0049, 0.0029]])      # 0.1 mm inside, near the edge y = z = max
    got = proj.project(p, np.array([1, 2]), np.array([1, 1]))
    assert np.allclose(got[0], [0.004, 0.005, 0.003], atol=1e-12)
    assert np.isclose(got[1, 1], 0.005) or np.isclose(got[1, 2], 0.003)
    assert not np.allclose(got[1], got[0])


def test_relaxed_closure_is_conforming_and_more_local_than_rivaras():
    """bisect's closure_ratio (refine.CLOSURE_RATIO): splitting an element at a marked edge of at least
    0.7 × its longest keeps the mesh conforming and nested, adds fewer elements than Rivara's closure
    (ratio 1: only at the longest edge), and keeps the smallest dihedral angle within 20 % of it
    (three levels of 12 % clustered marks on a 768-element annulus: 3419 against 6269 elements, 16.0° against 18.1°)."""
    from flexure.mesh import element_shape_metrics

    out = {}
    for ratio in (1.0, 0.7):
        rng = np.random.default_rng(5)
        tm = TaggedMesh.untagged(to_quadratic(cylinder_mesh(0.004, 0.012, 0.003, 4, 16, 2)))
        u = _quadratic(tm.mesh.points)
        for _ in range(3):
            c = tm.mesh.points[tm.mesh.corner_tets].mean(axis=1)
            marks = np.argsort(np.linalg.norm(c - c[rng.integers(len(c))], axis=1))[: len(c) // 8]
            tm, (u,), _ = bisect(tm, marks, [u], rounds=2, closure_ratio=ratio)
            check_conforming(tm.mesh)
            assert np.abs(u - _quadratic(tm.mesh.points)).max() < 1e-12
        out[ratio] = (tm.mesh.n_elements,
                      element_shape_metrics(tm.mesh.points, tm.mesh.corner_tets)["dihedral_deg"].min())
    assert out[0.7][0] < 0.8 * out[1.0][0]
    assert out[0.7][1] > 0.8 * out[1.0][1]


def test_morph_local_puts_nodes_on_the_surface_with_the_interior_following():
    """refine.morph_local (the second chance of bisect's projection): the outer mid nodes of a hollow
    cylinder, put back on their chords, go onto r = R; interior nodes within two layers move with
    them (harmonic extension), no element folds and none gets a new sliver."""
    from flexure.mesh import TET_EDGES, TET_FACES, element_shape_metrics
    from flexure.refine import _boundary_face_mask, mid_node_targets, morph_local

    R = 1.0
    mesh = to_quadratic(cylinder_mesh(0.5, R, 0.3, 3, 8, 2, order=1))
    tm = TaggedMesh.untagged(mesh)
    outer = np.hypot(*mesh.points[mesh.corner_tets][:, :, :2].transpose(2, 0, 1))[:, TET_FACES].min(axis=2) > R - 1e-9
    tm.face_tag[_boundary_face_mask(mesh) & outer] = 1
    t = mesh.tets
    for j, (a, b) in enumerate(TET_EDGES.tolist()):
        mesh.points[t[:, 4 + j]] = 0.5 * (mesh.points[t[:, a]] + mesh.points[t[:, b]])
    before = mesh.points.copy()
    angle0 = element_shape_metrics(mesh.points, mesh.corner_tets)["dihedral_deg"].min()
    nodes, dims, tags = mid_node_targets(tm)
    out = morph_local(mesh, nodes, dims, tags, _Cylinder(R))
    assert out["projected"] == len(nodes) > 20 and len(out["pending"][0]) == 0
    assert np.abs(np.hypot(mesh.points[nodes, 0], mesh.points[nodes, 1]) - R).max() < 1e-12
    interior = np.setdiff1d(np.arange(mesh.n_nodes), mesh.boundary_nodes())
    assert (np.linalg.norm(mesh.points[interior] - before[interior], axis=1) > 0).sum() > 10
    assert quality(mesh)["n_inverted"] == 0
    assert element_shape_metrics(mesh.points, mesh.corner_tets)["dihedral_deg"].min() >= min(angle0, 10.0) - 0.5


def test_straightening_reports_what_it_cannot_mend():
    """A curved mid node that folds an element is put back straight; a flat straight element is reported."""
    from flexure.refine import straighten_invalid

    tm = TaggedMesh.untagged(to_quadratic(box_mesh(2, 2, 2)))
    assert straighten_invalid(tm) == (0, 0)
    t = tm.mesh.tets[0]
    tm.mesh.points[t[4]] += 0.9 * (tm.mesh.points[t[3]] - tm.mesh.points[t[4]])     # a mid node pushed far: folded
    tm.mesh._cache.clear()
    moved, left = straighten_invalid(tm)
    assert moved >= 1 and left == 0
    p = tm.mesh.points
    p[t[3]] = p[t[0]] + 0.3 * (p[t[1]] - p[t[0]]) + 0.3 * (p[t[2]] - p[t[0]])       # vertex 3 on face 012: flat
    tm.mesh._cache.clear()
    assert straighten_invalid(tm)[1] >= 1


def _box_tagged(nx, ny, nz, jitter, seed):
    """A P2 box mesh, interior vertices jittered (distinct edge lengths; 0: the box's ties), each side
    its own surface tag 1..6 and every element edge along a box edge in x or y a curve tag 10 + its
    direction (one along z is seen as on either of its two surfaces: the strongest target's ties)."""
    from flexure.mesh import TET_EDGES, TET_FACES
    from flexure.refine import _boundary_face_mask

    rng = np.random.default_rng(seed)
    mesh = box_mesh(nx, ny, nz, size=(1.0, 0.7, 1.2))
    lo, hi = mesh.points.min(axis=0), mesh.points.max(axis=0)
    inner = np.all((mesh.points > lo + 1e-9) & (mesh.points < hi - 1e-9), axis=1)
    mesh.points[inner] += jitter * (rng.random((inner.sum(), 3)) - 0.5) / max(nx, ny, nz)
    mesh = to_quadratic(mesh)
    tm = TaggedMesh.untagged(mesh)
    P = mesh.points[mesh.corner_tets]                                      # (m,4,3)
    side = np.stack([np.isclose(P, lo), np.isclose(P, hi)], axis=-1)        # (m,4,3,2) vertex on x/y/z lo/hi
    bf = _boundary_face_mask(mesh)
    for f in range(4):
        on = side[:, TET_FACES[f]].all(axis=1).reshape(-1, 6)              # the face's 3 vertices on a side
        tm.face_tag[:, f] = np.where(bf[:, f] & on.any(axis=1), 1 + on.argmax(axis=1), 0)
    for j, (a, b) in enumerate(TET_EDGES.tolist()):
        both = (side[:, a] & side[:, b]).any(axis=2)                       # (m,3): the edge on a side ⊥ x, y, z
        along = both.sum(axis=1) == 2                                      # on two sides: a box edge
        axis = (~both).argmax(axis=1)                                      # the box edge's direction
        tm.edge_tag[:, j] = np.where(along & (axis < 2), 10 + axis, 0)     # along z: two surfaces' edge
    return tm


def _same(a, b):
    """Bit for bit: points, tets (order too), tags, fields, projection targets, counts."""
    assert a[0].tobytes() == b[0].tobytes()
    for x, y in zip(a[1:4], b[1:4]):
        assert np.array_equal(x, y)
    assert all(x.tobytes() == y.tobytes() for x, y in zip(a[4], b[4]))
    assert len(a[5]) == len(b[5]) and all(np.array_equal(x, y) for g, h in zip(a[5], b[5]) for x, y in zip(g, h))
    assert a[6:8] == b[6:8]


@pytest.mark.parametrize("jitter,ratio,rounds,bulge", [(0.0, 1.0, 1, 0.0), (0.5, 1.0, 3, 0.0), (0.5, 0.7, 1, 0.0),
                                                      (0.3, 0.7, 3, 0.0), (0.5, 1.0, 3, 0.2)])
def test_active_set_passes_equal_the_whole_mesh_reference(jitter, ratio, rounds, bulge):
    """refine.bisect's passes on the active set (flexure._refine_kernels) give the whole-mesh reference's
    (refine._passes_reference) mesh bit for bit: points, element order, face and edge tags, prolongated
    fields, projection targets, passes; over three successive refinements of random marks on a tagged,
    jittered box (ties of equal lengths without jitter), Rivara's closure and the relaxed one, and with
    mid nodes bulged off their chords (``bulge``: split edges' mid nodes that would fold a child go back
    on the chord, some of them vertices already); and the topology-only trial (bisected_dofs) counts the
    same DOFs."""
    from flexure._refine_kernels import passes
    from flexure.mesh import Mesh
    from flexure.refine import _passes_reference, bisected_dofs

    tm = _box_tagged(4, 3, 4, jitter, seed=int(10 * jitter) + rounds)
    rng = np.random.default_rng(rounds)
    mids = np.unique(tm.mesh.tets[:, 4:])
    tm.mesh.points[mids] += bulge * (rng.random((len(mids), 3)) - 0.5) / 4
    points, tets, ft, et = tm.mesh.points, tm.mesh.tets, tm.face_tag, tm.edge_tag
    fields = [_quadratic(points), rng.random((len(points), 3, 2))]
    assert (ft > 0).sum() > 50 and (et > 0).sum() > 20
    for step in range(3 if bulge == 0 else 2):              # bulged: the third grows tenfold
        marks = np.flatnonzero(rng.random(len(tets)) < 0.12)
        ref = _passes_reference(points, tets, ft, et, marks, fields, rounds, ratio)
        new = passes(points, tets, ft, et, marks, fields, rounds, ratio)
        _same(new, ref)
        assert ref[6] >= rounds and len(ref[1]) > len(tets)
        trial = TaggedMesh(Mesh(points, tets), ft, et)
        assert bisected_dofs(trial, marks, rounds, ratio) == 3 * len(ref[0])
        points, tets, ft, et, fields = ref[:5]
        check_conforming(Mesh(points, tets))
        if bulge == 0:                        # a mid node put back on its chord is not the quadratic's
            assert np.abs(fields[0] - _quadratic(points)).max() < 1e-12


@pytest.mark.slow
def test_active_set_passes_equal_the_reference_on_a_design_mesh():
    """As above on the paper disc's first adaptive mesh (gmsh, CAD surface and curve tags, snapped onto
    the true geometry), random marks, 1 and 3 rounds, Rivara's closure and 0.7."""
    from flexure._refine_kernels import passes
    from flexure.adaptive import geometry, start_mesh
    from flexure.design import load_design
    from flexure.refine import _passes_reference

    d = load_design("designs/paper_disc.toml")
    tm, proj = geometry(d, start_mesh(d))
    snap(tm, proj)
    rng = np.random.default_rng(0)
    u = rng.random((tm.mesh.n_nodes, 3, 6))
    for rounds, ratio in ((1, 1.0), (3, 1.0), (3, 0.7)):
        marks = np.flatnonzero(rng.random(tm.mesh.n_elements) < 0.05)
        args = (tm.mesh.points, tm.mesh.tets, tm.face_tag, tm.edge_tag, marks, [u], rounds, ratio)
        _same(passes(*args), _passes_reference(*args))


def test_straightening_after_a_bisection_checks_only_what_changed_and_finds_the_same(monkeypatch):
    """bisect's straighten_invalid skips the elements its input was found valid with (TaggedMesh.valid,
    by snap's morph or the bisection before) whose nodes did not move: two refinements of a curved hollow cylinder with projection give the
    same mesh bit for bit as checking every element, and the second check is smaller."""
    import flexure.refine as refine
    from flexure.mesh import TET_FACES
    from flexure.refine import _boundary_face_mask

    def run():
        R = 1.0
        mesh = to_quadratic(cylinder_mesh(0.5, R, 0.4, 2, 12, 2, order=1))
        tm = TaggedMesh.untagged(mesh)
        outer = np.hypot(*mesh.points[mesh.corner_tets][:, :, :2].transpose(2, 0, 1))[:, TET_FACES].min(axis=2) > R - 1e-9
        tm.face_tag[_boundary_face_mask(mesh) & outer] = 1
        snap(tm, _Cylinder(R))
        u = _quadratic(tm.mesh.points)
        for _ in range(2):
            c = tm.mesh.points[tm.mesh.corner_tets].mean(axis=1)
            tm, (u,), info = bisect(tm, np.flatnonzero(c[:, 0] > 0.2), [u], rounds=2, projector=_Cylinder(R))
            assert tm.valid is not None and info["invalid_elements"] == 0
        return tm, u

    sizes = []
    real = refine.straighten_invalid
    monkeypatch.setattr(refine, "straighten_invalid",
                        lambda tm, known=None: sizes.append(None if known is None else (~known).sum()) or real(tm, known=known))
    fast, uf = run()
    monkeypatch.setattr(refine, "_known_valid", lambda *a: None)
    slow, us = run()
    assert 0 < sizes[0] < sizes[1] < fast.mesh.n_elements and sizes[2:] == [None, None]    # snap (morph) left it valid
    assert fast.mesh.points.tobytes() == slow.mesh.points.tobytes() and np.array_equal(fast.mesh.tets, slow.mesh.tets)
    assert uf.tobytes() == us.tobytes()


def test_a_curved_mid_node_that_would_fold_a_child_goes_back_on_its_chord():
    """A thin element whose longest edge's mid node bulges past the opposite face (h = 0.2 above the
    chord of a 0.064-det element: either child, with the mid node as a vertex, has det 0.032 − 0.25 h < 0):
    the split puts it on the chord, each child is the straight half (det D/2), and an untouched split
    (a bulge of 0.01) keeps its curved node."""
    from flexure.mesh import Mesh

    corners = np.array([[0, 0, 0], [1, 0, 0], [0.5, 0.8, 0], [0.5, 0.3, 0.08]], float)
    for h, on_chord in ((0.2, True), (0.01, False)):
        mesh = to_quadratic(Mesh(corners.copy(), np.array([[0, 1, 2, 3]])))
        mid = mesh.tets[0, 4]                                   # edge (0, 1), the longest
        mesh.points[mid] = [0.5, 0.0, h]
        out, _, _ = bisect(TaggedMesh.untagged(mesh), [0])
        X = out.mesh.points[out.mesh.tets[:, :4]]
        det = np.linalg.det(np.stack([X[:, 1] - X[:, 0], X[:, 2] - X[:, 0], X[:, 3] - X[:, 0]], axis=2))
        assert len(det) == 2
        if on_chord:
            assert np.allclose(out.mesh.points[mid], [0.5, 0.0, 0.0]) and np.allclose(np.abs(det), 0.032)
        else:
            assert out.mesh.points[mid][2] == 0.01 and np.allclose(np.abs(det), 0.032 - 0.25 * 0.01)
