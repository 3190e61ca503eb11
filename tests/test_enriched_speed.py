"""The compiled assembly of the enriched system (flexure.enriched_assembly) against the numpy form it
replaces (flexure.enriched ``assemble``, ``coupling_matrix``, ``_block_jacobi``): the same K_WW, r_W,
coupling and block-Jacobi inverse to round-off on a distorted curved mesh with constrained surplus
functions, and the same enriched solve with either. No timings (benchmarks/bench_fem_enriched.py)."""

import numpy as np
import pytest

from flexure import enriched, enriched_assembly
from flexure.material import Material
from flexure.mesh import box_mesh, to_linear, to_quadratic

pytestmark = pytest.mark.skipif(not enriched_assembly.available(), reason="numba not installed")

AL = Material(70e9, 0.33, 270e6, "aluminium")


def _curved_box():
    """A distorted P2 box with bent mid nodes (curved elements) and a smooth non-polynomial field."""
    rng = np.random.default_rng(5)
    m = to_quadratic(to_linear(to_quadratic(box_mesh(3, 3, 4, size=(1.0, 0.8, 1.3)))))
    m.points[:] += rng.normal(size=m.points.shape) * 0.02
    x = m.points
    u = np.column_stack([np.sin(2 * x[:, 0]) * x[:, 2], np.cos(x[:, 1] * x[:, 0]), x[:, 2] ** 3 - x[:, 1]]) * 1e-3
    return m, u


@pytest.mark.parametrize("constrain", ["none", "bottom_and_top"])
def test_compiled_assembly_equals_the_numpy_form(constrain):
    mesh, u = _curved_box()
    cons = np.zeros(mesh.n_nodes, bool)
    if constrain != "none":
        z = mesh.points[:, 2]
        cons[(z < 0.1) | (z > 1.2)] = True
    K0, r0, num = enriched.assemble(mesh, AL, u, cons)
    keep = np.repeat(num[2], 3)
    assert keep.sum() < len(keep) or constrain == "none"
    K0 = K0[keep][:, keep].tocsr()
    C0 = enriched.coupling_matrix(mesh, AL, num)[:, keep].tocsr()
    K1, r1, C1, Dinv1, num1 = enriched_assembly.assemble_enriched(mesh, AL, u, enriched.surplus_numbering(mesh, cons))
    for a, b in zip(num, num1):
        assert np.array_equal(a, b)
    assert K1.shape == K0.shape and C1.shape == C0.shape
    assert abs(K1 - K0).max() <= 1e-12 * abs(K0).max()
    assert abs(C1 - C0).max() <= 1e-12 * abs(C0).max()
    assert abs(K1 - K1.T).max() <= 1e-12 * abs(K0).max()
    assert np.abs(r1 - r0[keep]).max() <= 1e-10 * np.abs(r0).max()
    D0 = enriched._block_jacobi(K0)
    assert np.abs(Dinv1 - D0).max() <= 1e-9 * np.abs(D0).max()


def test_enriched_solve_is_the_same_with_the_compiled_assembly(monkeypatch):
    """The rigidly coupled bar of tests/test_enriched.py: θ⁺ − θ_h and the gauge's J(u⁺) − J(u_h)
    from the compiled assembly (coupling applied through T and the Dirichlet mask in the product)
    and from the numpy form agree to the CG's round-off (the compiled path's scalar CSR storage: the
    float32 blocks in tests/test_block_sparse.py)."""
    from estimator import compiled
    from test_enriched import _bar_unit_rotation

    mesh, pr, sy, lu, g, cons, i_th, q, U = _bar_unit_rotation()
    out = []
    for on in (True, False):
        monkeypatch.setattr(compiled, "ENABLED", on)
        d_eps, d_th, info = enriched.enriched_solve(sy, mesh, AL, [g], U, q, cons, lambda R: lu.solve(R),
                                                    rtol=1e-12, theta_index=i_th, storage="csr")
        out.append((d_eps[0], d_th, info["enriched_dofs"]))
    assert out[0][2] == out[1][2]
    assert out[0][0] == pytest.approx(out[1][0], rel=1e-9)
    assert out[0][1] == pytest.approx(out[1][1], rel=1e-9) and out[0][1] > 0
