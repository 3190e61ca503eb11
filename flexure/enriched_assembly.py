"""The enriched system of flexure.enriched assembled by compiled loops (flexure._enriched_kernels):
each element's surplus stiffness, coupling and residual computed once and added straight into CSR
arrays whose pattern comes from the numbering (no per-chunk COO → CSR, no sparse sums, the
constrained surplus functions never assembled). The element loop runs colour by colour on
flexure.threads' threads (flexure._enriched_kernels.colour_elements: no two elements of a colour
share a node, so their additions never collide, and the sums do not depend on the thread count).
The numpy form (flexure.enriched ``assemble`` and ``coupling_matrix``) is the reference it is tested
against and the path without numba."""

from __future__ import annotations

import numpy as np

from flexure.mesh import Mesh


def available() -> bool:
    """True where the compiled assembly runs (numba installed and estimator.compiled enabled)."""
    from estimator import compiled

    return compiled.available()


def assemble_enriched(mesh: Mesh, material, u: np.ndarray, numbering, traction=None):
    """The enriched system on the free surplus functions of ``numbering`` (G, sign, free: flexure.enriched.surplus_numbering):
    → (K_WW (3 n_free square CSR, rows 3k + i, k the free functions in order), r_W (3 n_free,),
    K_hW (3 n_nodes × 3 n_free CSR, the full nodal rows: no coupling or Dirichlet reduction), the
    inverse 3 × 3 diagonal blocks of K_WW (n_free,3,3), the numbering (G, sign, free))."""
    from flexure import _enriched_kernels as ek
    from flexure import threads
    from flexure.stiffness_assembly import block_csr as _csr
    from flexure.fem import tet_shape
    from flexure.surplus import surplus_basis, tet_rule_degree5

    G, sign, free = numbering
    nk, Gk, tets = _free_functions(mesh, numbering)
    nt = threads.use()
    kb, kc = ek.block_pattern(Gk, Gk, nk, nk, nt)
    K = _csr(kb, kc, nk, nk)
    cb, cc = ek.block_pattern(tets, Gk, mesh.n_nodes, nk, nt)
    C = _csr(cb, cc, mesh.n_nodes, nk)
    rhs = _face_terms(mesh, material, u, traction)
    xi, wq = tet_rule_degree5()
    _, dN = tet_shape(2, xi)
    _, dB = surplus_basis(xi)
    r = np.zeros(3 * nk)
    D = np.zeros((nk, 3, 3))
    nt = threads.use()
    with threads.dynamic():                  # colour chunks handed out as threads come free
        ek.assemble(np.ascontiguousarray(mesh.points, float), tets, np.ascontiguousarray(np.asarray(u, float).reshape(-1, 3)),
                    np.ascontiguousarray(rhs), Gk, np.ascontiguousarray(sign), np.ascontiguousarray(dN),
                    np.ascontiguousarray(dB), np.ascontiguousarray(wq), float(material.lame_lambda_Pa),
                    float(material.shear_modulus_Pa), kb, kc, K.data, cb, cc, C.data, r, D,
                    *ek.colour_elements(np.ascontiguousarray(tets[:, :4]), mesh.n_nodes), 1 if nt == 1 else 8 * nt)
    return K, r, C, ek.inverse_blocks(D, 1 if nt == 1 else 8 * nt), (G, sign, free)


def assemble_enriched_blocks(mesh: Mesh, material, u: np.ndarray, numbering, dtype=np.float32, traction=None):
    """``assemble_enriched`` with K_WW and K_hW as flexure.block_sparse.BlockMatrix of values ``dtype``
    (float32: element terms computed in float64, summed into float32; 4.4 bytes an entry against
    12 in the scalar CSR): → (K_WW, r_W, K_hW, the inverse 3 × 3 diagonal blocks of K_WW (float64,
    summed in float64), the numbering)."""
    from flexure import _block_kernels as bk
    from flexure import _enriched_kernels as ek
    from flexure import rss, threads
    from flexure.block_sparse import BlockMatrix
    from flexure.fem import tet_shape
    from flexure.surplus import surplus_basis, tet_rule_degree5

    G, sign, free = numbering
    nk, Gk, tets = _free_functions(mesh, numbering)
    nt = threads.use()
    kb, kc, SK = ek.block_pattern_slots(Gk, Gk, nk, nk, nt)   # and each element block's place (no row search)
    kc = kc.astype(np.int32)
    cb, cc, SC = ek.block_pattern_slots(tets, Gk, mesh.n_nodes, nk, nt)
    cc = cc.astype(np.int32)
    K = BlockMatrix(kb, kc, np.zeros((len(kc), 3, 3), dtype), nk)
    C = BlockMatrix(cb, cc, np.zeros((len(cc), 3, 3), dtype), nk)
    rhs = _face_terms(mesh, material, u, traction)
    xi, wq = tet_rule_degree5()
    _, dN = tet_shape(2, xi)
    _, dB = surplus_basis(xi)
    r = np.zeros(3 * nk)
    D = np.zeros((nk, 3, 3))
    colours = ek.colour_elements(np.ascontiguousarray(tets[:, :4]), mesh.n_nodes)
    rss.now_gb(trim=True)       # the patterns' temporaries (free heap pages) returned before K and C are written
    with threads.dynamic():
        bk.assemble(np.ascontiguousarray(mesh.points, float), tets, np.ascontiguousarray(np.asarray(u, float).reshape(-1, 3)),
                    np.ascontiguousarray(rhs), Gk, np.ascontiguousarray(sign), np.ascontiguousarray(dN),
                    np.ascontiguousarray(dB), np.ascontiguousarray(wq), float(material.lame_lambda_Pa),
                    float(material.shear_modulus_Pa), SK, K.data, SC, C.data, r, D, *colours, 1 if nt == 1 else 8 * nt)
    return K, r, C, ek.inverse_blocks(D, 1 if nt == 1 else 8 * nt), (G, sign, free)


def _free_functions(mesh: Mesh, numbering):
    """(n_free, Gk (m,10) each element's surplus functions numbered among the free ones, −1 where
    constrained, the element table as int64) of a numbering (G, sign, free)."""
    G, _, free = numbering
    kept = np.cumsum(free) - 1
    return int(free.sum()), np.where(free[G], kept[G], -1).astype(np.int64), np.ascontiguousarray(mesh.tets, dtype=np.int64)


def _face_terms(mesh: Mesh, material, u: np.ndarray, traction=None) -> np.ndarray:
    """The face terms ∫_∂K t̂ · φ_b dA of each element's residual (m,10,3). Summed over the elements they
    cancel: on a shared face t̂_K' = ½(σ_K' + σ_K) n_K' = −t̂_K against the same global function, on a free
    face t̂ = 0, so the global r_W = −a(u_h, φ_W) needs none of them (zeros; measured on the thick and the
    STL discs' first meshes: r_W within 7e-15 of the sum with them, at 0.26–0.33 s of
    flexure.bank_weiser.face_rhs saved a level there). Only an applied ``traction`` is computed."""
    if traction is None:
        return np.zeros((mesh.n_elements, 10, 3))
    from flexure.bank_weiser import face_rhs

    return face_rhs(mesh, material, u, traction)
