"""The global stiffness assembled by a compiled element loop (flexure._stiffness_kernels): the node-block
pattern from the element table (flexure._enriched_kernels.block_pattern), its scalar CSR (rows 3r + i,
the layout of flexure.fem.stiffness_matrix's BSR → CSR), each element's 3nn × 3nn matrix computed at
the quadrature points and added in place, colour by colour on flexure.threads' threads. The numpy
form (flexure.fem.stiffness_matrix without numba) is the reference it is tested against."""

from __future__ import annotations

import numpy as np

from flexure.mesh import Mesh


def available() -> bool:
    """True where the compiled assembly runs (numba installed and estimator.compiled enabled)."""
    from estimator import compiled

    return compiled.available()


def block_csr(bptr, bcol, n_rows: int, n_cols: int):
    """An all-zero scalar CSR (3 n_rows × 3 n_cols) of the block pattern (bptr, bcol): rows 3r + i,
    each block row's blocks in order, 3 columns each; int32 indices where they fit."""
    import scipy.sparse as sp

    from flexure import _enriched_kernels as ek

    nnz = 9 * int(bptr[-1])
    idx = np.int32 if max(nnz, 3 * n_cols) < 2 ** 31 - 1 else np.int64
    indptr = np.empty(3 * n_rows + 1, idx)
    indices = np.empty(nnz, idx)
    ek.scalar_csr(bptr, bcol, indptr, indices)            # parallel rows: thread count set by the caller
    M = sp.csr_matrix((3 * n_rows, 3 * n_cols))
    M.data, M.indices, M.indptr = np.zeros(nnz), indices, indptr        # sorted, canonical by construction
    return M


def stiffness_csr(mesh: Mesh, material, dN: np.ndarray, wq: np.ndarray):
    """K (3n × 3n CSR, canonical, int32 indices where they fit) with the quadrature's reference shape
    gradients dN (q,nn,3) and weights wq (q,). InputError on an element with det J ≤ 0 at a
    quadrature point (inverted or degenerate), as flexure.fem.physical_gradients."""
    from flexure import _enriched_kernels as ek
    from flexure import _stiffness_kernels as sk
    from flexure import threads
    from userio.errors import InputError

    tets = np.ascontiguousarray(mesh.tets, dtype=np.int64)
    n = mesh.n_nodes
    nt = threads.use()
    bptr, bcol, S = ek.block_pattern_slots(tets, tets, n, n, nt)   # and each element block's place
    K = block_csr(bptr, bcol, n, n)
    det = np.empty(len(tets))
    cptr, order = ek.colour_elements(np.ascontiguousarray(tets[:, :4]), n)
    nt = threads.use()
    with threads.dynamic():
        sk.assemble(np.ascontiguousarray(mesh.points, float), tets, np.ascontiguousarray(dN),
                    np.ascontiguousarray(wq, float), float(material.lame_lambda_Pa),
                    float(material.shear_modulus_Pa), bptr, S, K.data, det, cptr, order,
                    1 if nt == 1 else 8 * nt)
    bad = ~(det > 0)
    if np.any(bad):
        idx = int(np.flatnonzero(bad)[0])
        raise InputError(f"mesh: element {idx} is inverted or degenerate "
                         f"(det J = {float(det[idx]):.3e}); fix the mesh")
    return K



def chunks() -> int:
    """How many ranges a parallel element loop splits into: 8 per thread (1 on one thread)."""
    from flexure import threads

    n = threads.use()
    return 1 if n == 1 else 8 * n


def jacobians(X: np.ndarray, dN: np.ndarray):
    """det J (e,q) and J⁻¹ (e,q,3,3) (J⁻¹[k,i] = ∂ξ_k/∂x_i) of elements with nodes X (e,nn,3) at
    points with reference shape gradients dN (q,nn,3), compiled (flexure._stiffness_kernels)."""
    from flexure import _stiffness_kernels as sk
    from flexure import threads

    X = np.ascontiguousarray(X, dtype=float)
    det = np.empty((len(X), dN.shape[0]))
    Jinv = np.empty((len(X), dN.shape[0], 3, 3))
    n = chunks()
    with threads.dynamic():
        sk.jacobians(X, np.ascontiguousarray(dN, dtype=float), det, Jinv, n)
    return det, Jinv


def gradients(X: np.ndarray, dN: np.ndarray):
    """∂N_a/∂x_i (e,q,nn,3) and det J (e,q) (``jacobians``), compiled."""
    from flexure import _stiffness_kernels as sk
    from flexure import threads

    X = np.ascontiguousarray(X, dtype=float)
    G = np.empty((len(X), dN.shape[0], dN.shape[1], 3))
    det = np.empty((len(X), dN.shape[0]))
    n = chunks()
    with threads.dynamic():
        sk.gradients(X, np.ascontiguousarray(dN, dtype=float), G, det, n)
    return G, det
