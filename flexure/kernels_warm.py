"""The install-time compile of the FEM's parallel loops (run.sh calls ``warm``)."""

from __future__ import annotations

import numpy as np


def warm() -> bool:
    """Compile (and cache) the FEM's parallel loops on a tiny mesh — the stiffness, the enriched
    assembly (CSR and 3 × 3 blocks), the sparse products, the block Gauss–Seidel, the coupling's condensation,
    the element-nodal strains, the STL's closest points and the curved elements' validity check — so that the first analysis does not pay numba's compile time
    (measured 30 + 14 + 9 s at load 4: benchmarks/bench_fem_parallel.py --cold); False without numba."""
    from flexure import stiffness_assembly

    if not stiffness_assembly.available():
        return False
    from flexure import enriched, enriched_assembly, fem, sparse_parallel, threads
    from flexure.bc import Problem
    from flexure.block_sparse import BlockMatrix
    from flexure.material import Material
    from flexure.mesh import box_mesh, to_quadratic

    m = to_quadratic(box_mesh(1, 1, 1))
    mat = Material(70e9, 0.33, 270e6, "warm-up")
    K = fem.stiffness_matrix(m, mat)
    top = np.flatnonzero(m.points[:, 2] == m.points[:, 2].max())
    prob = Problem(m, mat).fix(np.flatnonzero(m.points[:, 2] == 0))
    prob.couple_rigid(top, (0.5, 0.5, 1.0))
    prob.reduced_system(K)                       # flexure.reduce's loop (Tᵀ K T)
    C = enriched_assembly.assemble_enriched(m, mat, np.zeros((m.n_nodes, 3)),
                                            enriched.surplus_numbering(m, np.zeros(m.n_nodes, bool)))[2]
    Kb, _, Cb, Dinv, _ = enriched_assembly.assemble_enriched_blocks(
        m, mat, np.zeros((m.n_nodes, 3)), enriched.surplus_numbering(m, np.zeros(m.n_nodes, bool)))
    from flexure.bank_weiser import face_rhs

    face_rhs(m, mat, np.zeros((m.n_nodes, 3)))   # the local problems' face term (the levels' estimate)
    from flexure import dwr
    from flexure.post import element_nodal_strains, stress_measures

    eps = element_nodal_strains(m, np.zeros((m.n_nodes, 3)))     # the peak stresses' strains (flexure._strain_kernels)
    stress_measures(eps, mat)                                    # and their von Mises and max shear

    dwr.energy_indicators(m, mat, np.zeros((m.n_nodes, 3, 2)), np.zeros((m.n_elements, 6, 3)),
                          np.zeros((m.n_elements, 4, 3)))
    with threads.limited(2):
        BlockMatrix.from_csr(K)
        sparse_parallel.matvec(K, np.ones(K.shape[0]))
        sparse_parallel.rmatvec(C, np.ones(C.shape[0]))
        Cb.matvec(np.ones(Cb.shape[1]))
        Cb.rmatvec(np.ones(Cb.shape[0]))
        Cb.matvec_rmatvec(np.ones(Cb.shape[1]), np.ones(Cb.shape[0]))
        Kb.symmetric_gauss_seidel(Dinv, np.ones(Kb.shape[0]))
    from flexure._closest_kernels import closest_on_triangles
    from flexure.mesh_motion import element_valid

    closest_on_triangles(np.zeros((1, 3)), np.eye(3)[None], np.array([0, 1]), np.array([0]))
    element_valid(m, np.arange(len(m.tets)))
    return True
