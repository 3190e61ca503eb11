"""Independent converged references for the flexure FEM: scikit-fem P2 on fine meshes.

Only the P1 mesh (gmsh, the project's size field × ``h_factor``) and the node selections of the
design (which surface carries the load, which is held) are shared with the project; assembly,
boundary conditions and solve are scikit-fem's own (+ pyamg smoothed aggregation with the
rigid-body modes as CG preconditioner).

Torque: the bore faces turn rigidly by θ about the z axis through (0, 0, t/2) (prescribed
u = θ e_z × x on every bore dof), the held faces are clamped. For a part with n ≥ 2-fold rotational
symmetry about z and a mid-plane mirror (every extruded spoke disc), this equals the project's
kinematic coupling under a pure M_z (the coupling's other five rigid modes carry no load by
symmetry). Then

    T = uᵀ K u / θ         (reaction torque from the strain energy: 2U = Tθ)
    k = T / θ              (N·m/rad)
    ε_g per N·m = (1/LW)∫∫ aᵀ ε a dA / T   over the same footprint pieces as flexure.gauges.read_footprint
                                           (the grid clipped by the mesh's faces; exact for P2 strain)

Run:  python benchmarks/fem_reference.py DESIGN.toml [h_factor ...]     (prints one JSON line per level)
      python benchmarks/fem_reference.py --project DESIGN.toml 1.414 1 0.707   (the project's levels,
      as stored in tests/data/fem_reference/levels.json)
"""

from __future__ import annotations

import json
import sys
import time

import numpy as np


def reference(design, h_factor: float, rtol: float = 1e-10) -> dict:
    """scikit-fem P2 gauge strain per N·m (bridge ε_ref) and stiffness on the design's mesh × h_factor."""
    import pyamg
    import scipy.sparse.linalg as spla
    import skfem
    from skfem.models.elasticity import lame_parameters, linear_elasticity

    from flexure.analysis import _selections, build_mesh
    from flexure.gauges import bridge_strains, footprint_pieces, sample_points

    t0 = time.perf_counter()
    m1 = build_mesh(design, order=1, h_factor=h_factor, max_elements=5e6).mesh
    load_nodes, fixed_nodes = _selections(design, m1)
    sm = skfem.MeshTet(m1.points.T.copy(), m1.tets.T.astype(np.int64).copy())
    basis = skfem.Basis(sm, skfem.ElementVector(skfem.ElementTetP2()))
    mat = design.material
    K = linear_elasticity(*lame_parameters(mat.E_Pa, mat.nu)).assemble(basis).tocsr()
    bf = sm.boundary_facets()

    def facets_of(nodes):
        on = np.zeros(sm.nvertices, bool)
        on[nodes] = True
        return bf[on[sm.facets[:, bf]].all(axis=0)]

    fixed_dofs = basis.get_dofs(facets=facets_of(fixed_nodes)).all()
    load_dofs = np.setdiff1d(basis.get_dofs(facets=facets_of(load_nodes)).all(), fixed_dofs)
    comp = np.empty(basis.N, dtype=np.int64)
    for c in range(3):
        comp[basis.nodal_dofs[c]] = c
        comp[basis.edge_dofs[c]] = c
    z_mid = 0.5 * (m1.points[:, 2].min() + m1.points[:, 2].max())
    theta = 1e-3
    x = np.zeros(basis.N)
    loc = basis.doflocs[:, load_dofs]
    x[load_dofs] = np.where(comp[load_dofs] == 0, -theta * loc[1], np.where(comp[load_dofs] == 1, theta * loc[0], 0.0))
    D = np.union1d(fixed_dofs, load_dofs)
    A, b, xD, I = skfem.condense(K, np.zeros(basis.N), x=x, D=D)
    # rigid-body modes of the free dofs (near-null space for smoothed aggregation)
    p = basis.doflocs[:, I] - basis.doflocs[:, I].mean(axis=1, keepdims=True)
    cI = comp[I]
    B = np.zeros((len(I), 6))
    for c in range(3):
        B[cI == c, c] = 1.0
    B[cI == 0, 3], B[cI == 1, 3] = -p[1, cI == 0], p[0, cI == 1]
    B[cI == 1, 4], B[cI == 2, 4] = -p[2, cI == 1], p[1, cI == 2]
    B[cI == 2, 5], B[cI == 0, 5] = -p[0, cI == 2], p[2, cI == 0]
    ml = pyamg.smoothed_aggregation_solver(A.tocsr(), B=B, max_coarse=500, coarse_solver="splu")
    its = []
    uI, info = spla.cg(A, b, rtol=rtol, M=ml.aspreconditioner(), maxiter=3000, callback=lambda _: its.append(1))
    if info != 0:
        raise RuntimeError(f"CG did not converge ({info})")
    u = xD.copy()
    u[I] = uI
    torque = float(u @ (K @ u)) / theta
    # gauge read-out at the project's Gauss points, with scikit-fem's own interpolation
    finder = sm.element_finder()
    readings = []
    for g in design.gauges:
        pieces = footprint_pieces(g, m1)          # the grid cut by the mesh's faces: exact area mean
        if pieces is None:
            pts, w = sample_points(g)
            elems = finder(*pts.T)
        else:
            elems, pts, w = pieces
        a = g.frame()[1]
        eps_a = np.empty(len(pts))
        for k in range(len(pts)):
            X = sm.mapping().invF(pts[k][:, None, None], tind=np.array([elems[k]]))[:, 0, :]
            cb = skfem.CellBasis(sm, basis.elem, elements=np.array([elems[k]]), quadrature=(X, np.ones(1)))
            H = cb.interpolate(u).grad[:, :, 0, 0]
            eps_a[k] = a @ (0.5 * (H + H.T)) @ a
        readings.append(float(w @ eps_a))
    eps = bridge_strains(design.gauges, np.array(readings)) / torque
    return {"h_factor": h_factor, "dofs": int(basis.N), "cg_iterations": len(its),
            "gauge_strain_per_Nm": float((eps[0] - eps[1] + eps[2] - eps[3]) / 4.0),
            "torsional_stiffness_Nm_per_rad": torque / theta, "seconds": time.perf_counter() - t0}


def project_level(design, h_factor: float) -> dict:
    """The project's own answer on one level (flexure.analysis.analyze), in the form that
    tests/data/fem_reference/levels.json stores and flexure.convergence estimates from."""
    from flexure.analysis import analyze
    from flexure.convergence import level_record

    res, _ = analyze(design, h_factor=h_factor)
    lv = level_record(design, res, h_factor)
    return {**{k: lv[k] for k in ("h_factor", "dofs", "gauge_elements", "gauge_strain_per_Nm",
                                  "torsional_stiffness_Nm_per_rad")},
            "gauge_arm_imbalance": res["gauge_arm_imbalance"], "min_dihedral_deg": res["mesh"]["min_dihedral_deg"]}


def main(argv: list[str]) -> int:
    from flexure.design import load_design

    project = "--project" in argv
    argv = [a for a in argv if a != "--project"]
    design = load_design(argv[0])
    for f in [float(v) for v in argv[1:]] or [0.5]:
        print(json.dumps(project_level(design, f) if project else reference(design, f)), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
