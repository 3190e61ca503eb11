"""flexure.node_order: a bisected mesh's nodes renumbered along a Morton curve are the same mesh (each
element's nodes at the same places, the fields and pending nodes following them), with the nodes of
an element close in the numbering, and the goal solve on it gives the same goals."""

import numpy as np
import pytest

from skew_annulus import skew_annulus


@pytest.fixture(scope="module")
def bisected(tmp_path_factory):
    """A P2 start mesh bisected once where its elements are closest to the bore (new nodes appended
    after gmsh's), with a nodal field and a validity record."""
    from flexure.analysis import build_mesh
    from flexure.refine import TaggedMesh, bisect, straighten_invalid

    design = skew_annulus(tmp_path_factory.mktemp("node_order"))
    mesh = build_mesh(design, "coarse", 2, 2.0).mesh
    tm = TaggedMesh.untagged(mesh)
    r = np.linalg.norm(mesh.points[mesh.tets[:, :4]].mean(axis=1)[:, :2], axis=1)
    field = np.column_stack([mesh.points[:, 0] ** 2, mesh.points[:, 1], np.ones(mesh.n_nodes)])
    new, (f,), _ = bisect(tm, np.flatnonzero(r < np.quantile(r, 0.3)), [field], rounds=2)
    straighten_invalid(new)
    return design, new, f


def _span(mesh) -> float:
    t = mesh.tets.astype(np.int64)
    return float(np.median(t.max(axis=1) - t.min(axis=1)))


def test_renumbered_mesh_is_the_same_mesh_with_local_numbers(bisected):
    from flexure.node_order import renumbered

    _, tm, f = bisected
    tm.pending = (np.array([0, tm.mesh.n_nodes - 1]), np.array([2, 2]), np.array([1, 1]))
    out, (g,), perm = renumbered(tm, (f,))
    assert np.array_equal(np.sort(perm), np.arange(tm.mesh.n_nodes))
    # every element's nodes at the same places, in the same local order; tags unchanged
    assert np.array_equal(out.mesh.points[out.mesh.tets], tm.mesh.points[tm.mesh.tets])
    assert out.face_tag is tm.face_tag and out.edge_tag is tm.edge_tag
    # a nodal field follows its nodes: the same value at the same point
    assert np.array_equal(g[out.mesh.tets], f[tm.mesh.tets])
    inv = np.empty_like(perm)
    inv[perm] = np.arange(len(perm))
    assert np.array_equal(out.pending[0], inv[tm.pending[0]])
    # the validity record renumbered with the mesh: the next bisection's incremental check still applies
    assert np.array_equal(out.valid[1], out.mesh.tets) and np.array_equal(out.valid[2], out.mesh.points)
    # the purpose: an element's nodes close together in the numbering (measured 22 k → 1.8 k on the
    # thick disc's 118 k nodes)
    assert _span(out.mesh) < 0.5 * _span(tm.mesh)


def test_goals_on_the_renumbered_mesh_are_the_same(bisected):
    """The goal solve (θ and every gauge, dual-corrected) on the renumbered mesh, its load and fixed
    node sets renumbered: the same goals to the CG's accuracy (another node order is another
    Gauss–Seidel order and another AMG aggregation)."""
    from flexure import goals
    from flexure.adaptive import _band_indicator, _nested_selections, goal_values
    from flexure.analysis import _selections
    from flexure.node_order import renumbered

    design, tm, _ = bisected
    bands = _band_indicator(tm.mesh, _selections(design, tm.mesh))
    out, (bands_r,), _ = renumbered(tm, (bands,))
    vals = []
    for mesh, b in ((tm.mesh, bands), (out.mesh, bands_r)):
        sol = goals.solve_goals(design, mesh, selections=_nested_selections(mesh, b), rtol=1e-10)
        v = goal_values(design, sol)
        vals.append(np.r_[v["theta"], v["eps"]])
    scale = np.r_[abs(vals[0][0]), np.full(len(vals[0]) - 1, np.abs(vals[0][1:]).max())]
    assert np.all(np.abs(vals[1] - vals[0]) <= 1e-7 * scale)
