"""The goals of a flexure design on one mesh: the torque case and the gauges' dual problems solved
together (one matrix, one preconditioner, 1 + g right-hand sides), the goal values and their
dual-weighted-residual indicators (flexure.dwr).

Goals, all for a unit torque M_z at the reference point (0, 0, t/2):

    θ = rotation of the hub (rigid coupling: its reference rotation; distributed: the traction's
        work-conjugate mean rotation) = F(u): the compliance, its own dual (stiffness k = 1/θ);
    ε_g = gauge g's read-out (flexure.gauges.functionals: F_gᵀ u), dual z_g: a(v, z_g) = F_gᵀ v.

The duals are right-hand sides of the same reduced system (A z = Tᵀ F_g), so they cost one more
column each in the multi-column CG (flexure.multirhs).
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

#: CG tolerance of the goal solves: 1e-6 and 1e-8 give goal values within 1e-9 relative (paper disc)
GOAL_RTOL = 1e-6


@dataclass
class GoalSolution:
    """Nodal fields U (n, 3, 1 + g): the torque case then the gauges' duals; θ; gauge readings
    ε (g,); constrained nodes (clamped or rigidly coupled: the DWR weight vanishes there); the
    reduced solution q (n_q, 1 + g) and the Problem/system (prolongation, final solve)."""

    U: np.ndarray
    theta: float
    eps: np.ndarray
    constrained: np.ndarray
    q: np.ndarray
    info: dict
    traction: list
    K: object = None            # the stiffness matrix and the prepared solver of the system (solve.prepared):
    solver: object = None       # the last level's remaining load cases reuse them
    system: object = None       # the reduced system (flexure.enriched's error solve)


def solve_goals(design, mesh, x0_fields=None, x0_ref=None, rtol: float | None = None,
                selections=None) -> GoalSolution:
    """Assemble and solve the torque case with the gauges' duals on ``mesh``; ``x0_fields``
    (n, 3, 1 + g) and ``x0_ref`` (the reference dofs (6, 1 + g)) give the CG's initial guess;
    ``selections`` the (load, fixed) node sets (default: the design's radius bands on ``mesh``)."""
    from flexure import solve as fsolve
    from flexure.analysis import SMOOTHED_COARSE, _selections
    from flexure.bc import Problem, wrench_traction
    from flexure.fem import stiffness_matrix
    from flexure.gauges import functionals, read_footprint

    t0 = time.perf_counter()
    load, fixed = _selections(design, mesh) if selections is None else selections
    problem = Problem(mesh, design.material).fix(fixed)
    ref = np.array([0.0, 0.0, 0.5 * (mesh.points[:, 2].min() + mesh.points[:, 2].max())])
    K = stiffness_matrix(mesh, design.material)
    F = functionals(design.gauges, mesh)                                     # (n, 3, g)
    g = F.shape[2]
    constrained = np.zeros(mesh.n_nodes, bool)
    constrained[fixed] = True
    traction = []
    if design.coupling == "rigid":
        problem.couple_rigid(load, ref, kind="kinematic")
        constrained[load] = True
        system = problem.reduced_system(K)
        fsolve._check_restrained(system)
        B = np.zeros((system.A.shape[0], 1 + g))
        B[system.ref_slices[0].start + 5, 0] = 1.0
    else:
        is_load = np.zeros(mesh.n_nodes, bool)
        is_load[load] = True
        faces = mesh.boundary_faces()
        faces = faces[is_load[faces].all(axis=1)]
        system = problem.reduced_system(K)
        fsolve._check_restrained(system)
        B = np.zeros((system.A.shape[0], 1 + g))
        B[:, 0] = wrench_traction(mesh, faces, ref, moment_Nm=(0, 0, 1)).ravel()
        traction.append((faces, ref))
    T = system.T
    B[:, 1:] = F.reshape(-1, g) if T is None else T.T @ F.reshape(-1, g)
    B[system.fixed_q] = 0.0
    assemble_s = time.perf_counter() - t0
    x0 = None if x0_fields is None else problem.restrict(system, x0_fields, x0_ref)
    solver = fsolve.prepared(system, rtol or GOAL_RTOL, SMOOTHED_COARSE[design.mesher])
    q, info = solver(B, x0)
    U = np.stack([problem.expand(system, q[:, j]) for j in range(1 + g)], axis=-1)
    theta = float(B[:, 0] @ q[:, 0])                                         # F(u) = θ for a unit torque
    eps = read_footprint(design.gauges, mesh, U[:, :, :1])[:, 0]
    info["assemble_s"] = assemble_s
    info["total_s"] = time.perf_counter() - t0
    return GoalSolution(U, theta, eps, constrained, q, info, traction, K, solver, system)


def indicators(design, mesh, sol: GoalSolution) -> np.ndarray:
    """Vertex DWR indicators (n, 1 + g) of θ and the gauge readings (flexure.dwr), with the
    distributed coupling's traction term F(w ψ_a) added to θ's column."""
    from flexure import dwr

    eta = dwr.dual_weighted_residuals(mesh, design.material, sol.U[:, :, 0], sol.U[:, :, 1:],
                                      design.gauges, sol.constrained)
    if sol.traction:
        ce, cf = dwr.primal_weight(mesh, sol.U[:, :, 0], sol.constrained)
        for faces, ref in sol.traction:
            eta[:, 0] += dwr.moment_traction_indicators(mesh, faces, ref, ce, cf)
    return eta
