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
#: the goals' algebraic error (``algebraic_errors``) must stay below this share of the adaptive
#: run's --rtol; the CG tolerance tied to it (``cg_rtol_for``), tightened ×1/100 until it does
ALGEBRAIC_SHARE = 0.01
#: the loosest CG tolerance used (the dual readings of the other load cases, goal_cases, carry an
#: error of the order of their own residual, not corrected)
CG_RTOL_MAX = 1e-4
#: the torque column's CG tolerance over the duals' in an adaptive run (its goals are dual-corrected
#: and their algebraic error checked after the solve, which decides): its load is one unit moment on
#: the coupling's reference DOF (‖b‖ = 1), while a prolongated start leaves residual forces at every
#: new node (thick disc: ‖r₀‖ 21 and 8.9 ‖b‖ on levels 1 and 2), so ‖r‖ ≤ rtol ‖b‖ took it 15–18
#: iterations where the duals took 3–10. At 10× the checked error came out 4e-6 – 2e-5 against the
#: 2e-4 limit of a 2 % run, 4–5 fewer iterations per level (thick disc, 2026-11-27).
TORQUE_RTOL_FACTOR = 10.0


#: the torque column's goal-oriented stop (``goal_stop``): every goal's estimated algebraic error below
#: this share of the limit, so that the check after the solve (its residual recomputed, not the CG's
#: recursive one) passes with room
GOAL_STOP_SHARE = 0.5
#: r₀ᵀ A⁻¹ r₀ ≤ this × r₀ᵀ M r₀ for the p-multigrid cycle M: 1/λ_min of MA (its spectrum within
#: [λ_min, 1]), measured by Lanczos 4.8 on the skew annulus (tests/test_goal_stop.py) and 7.8, 8.2,
#: 13.2 on the thick disc's adaptive levels of 83 k, 250 k, 354 k DOFs (2026-11-27). Where the stop
#: came, θ's term was 1e-3–1e-4 of the gauges' (thick disc at --rtol 0.01: 5e-7 against 5e-5 at 776 k)
PRECOND_ALLOWANCE = 100.0


def goal_stop(B: np.ndarray, limit: float):
    """The torque column's goal-oriented CG stop (flexure.multirhs.pcg ``goal_stop``; the iterative
    solver's error measured in the goals, Meidner, Rannacher & Vihharev 2009): once the duals have
    stopped (column 0 the only active one), it stops where

        max_g e_g / s_g ≤ GOAL_STOP_SHARE · limit,

    e_g = |z̃_gᵀ r₀| for a gauge (its dual-corrected reading is off by the second-order r_gᵀ A⁻¹ r₀:
    ``algebraic_errors``), and for θ, whose corrected value θ̃ + q̃ᵀ r₀ is off by r₀ᵀ A⁻¹ r₀ exactly,
    e_0 = PRECOND_ALLOWANCE · r₀ᵀ M r₀ (the CG's own rz); s_g the goals' scales (``solve_goals``).
    Where the l2 residual ‖r₀‖ ≤ rtol ‖b‖ comes first, that stops it as before."""

    def stop(X, R, rz, act):
        out = np.zeros(len(act), bool)
        if len(act) != 1 or act[0] != 0:
            return out
        J = B.T @ X[:, 0]
        err = np.abs(X.T @ R[:, 0])
        err[0] = PRECOND_ALLOWANCE * abs(float(rz[0]))
        out[0] = float(np.max(err / _scales(J))) <= GOAL_STOP_SHARE * limit
        return out

    return stop


def _scales(J: np.ndarray) -> np.ndarray:
    """The goals' scales: |θ|, and a gauge's max(|ε_g|, mean |ε|)."""
    scale = np.abs(J)
    scale[1:] = np.maximum(scale[1:], np.abs(J[1:]).mean())
    return np.maximum(scale, 1e-300)


def cg_rtol_for(rtol: float) -> float:
    """CG tolerance of the goal solves of an adaptive run to ``rtol``: min(CG_RTOL_MAX,
    ALGEBRAIC_SHARE · rtol); the goals' own algebraic error is then checked (``algebraic_errors``)."""
    return min(CG_RTOL_MAX, ALGEBRAIC_SHARE * rtol)


def algebraic_errors(B: np.ndarray, q: np.ndarray, R: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Goal values corrected for the CG's algebraic error, and that error, from the residuals
    R = B − A q̃ of the torque column (0) and the duals (1 …): with J_g = B_gᵀ q (B_0ᵀ q the compliance
    θ, B_gᵀ q the gauge readings, A symmetric, z_g the dual of goal g: z_0 = q_0),

        J_g − B_gᵀ q̃_0 = z_gᵀ r_0 = z̃_gᵀ r_0 + r_gᵀ A⁻¹ r_0,

    so J̃_g + z̃_gᵀ r_0 (the dual-corrected value) is off by the second-order r_gᵀ A⁻¹ r_0 only, and
    |z̃_gᵀ r_0| is the (first-order) algebraic error of the raw value: reported as the error of
    the corrected one, which it bounds wherever the residuals are small (the second-order term is
    then the product of two of them). → (J corrected (1 + g,), |z̃ᵀ r_0| (1 + g,))"""
    J = B.T @ q[:, 0]
    d = q.T @ R[:, 0]
    return J + d, np.abs(d)


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
    K: object = None            # not kept (freed before the solve; the load cases come from the duals, goal_cases)
    solver: object = None       # the prepared solver of the system (solve.prepared)
    system: object = None       # the reduced system (flexure.enriched's error solve)


def solve_goals(design, mesh, x0_fields=None, x0_ref=None, rtol: float | None = None,
                selections=None, algebraic_limit: float | None = None) -> GoalSolution:
    """Assemble and solve the torque case with the gauges' duals on ``mesh``; ``x0_fields``
    (n, 3, 1 + g) and ``x0_ref`` (the reference dofs (6, 1 + g)) give the CG's initial guess;
    ``selections`` the (load, fixed) node sets (default: the design's radius bands on ``mesh``);
    ``rtol`` the CG tolerance (default GOAL_RTOL). ``algebraic_limit``: the goals (θ, each gauge
    reading) are dual-corrected and their relative algebraic error (``algebraic_errors``; a gauge's
    relative to max(|ε_g|, mean |ε|)) is held below it, the torque column's CG first stopped at
    TORQUE_RTOL_FACTOR × ``rtol`` or where its goals are resolved (``goal_stop``), then every
    column tightened ×1/100 from its iterate until it is
    (info: ``goal_algebraic_error``, ``goal_algebraic_limit``, ``cg_rtol``)."""
    from flexure import rss
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
    del K, F                      # the reduced system holds its own matrix: free the full one before the solve
    rss.now_gb(trim=True)         # ... and the assembly's free heap pages: the solver's set-up comes on top
    assemble_s = time.perf_counter() - t0
    x0 = None if x0_fields is None else problem.restrict(system, x0_fields, x0_ref)
    solver = fsolve.prepared(system, rtol or GOAL_RTOL, SMOOTHED_COARSE[design.mesher])
    cg_rtol = rtol or GOAL_RTOL
    col_rtol = np.full(1 + g, cg_rtol)
    if algebraic_limit is not None:
        col_rtol[0] *= TORQUE_RTOL_FACTOR
    q, info = solver(B, x0, col_rtol, goal_stop=None if algebraic_limit is None else goal_stop(B, algebraic_limit))
    its = [info.get("iterations")]
    if algebraic_limit is not None:       # a loose CG: the goals dual-corrected, their algebraic error checked
        while True:
            J, err = algebraic_errors(B, q, B - system.A @ q)
            rel = float(np.max(err / _scales(J)))
            if rel <= algebraic_limit or cg_rtol <= 1e-10:
                break
            cg_rtol *= 1e-2                                    # tighter, from where it is
            q, info = solver(B, q, np.full(1 + g, cg_rtol))
            its.append(info.get("iterations"))
        info.update(goal_algebraic_error=rel, goal_algebraic_limit=algebraic_limit, cg_rtol=cg_rtol,
                    iterations=its[0] if len(its) == 1 else its)
    U = np.stack([problem.expand(system, q[:, j]) for j in range(1 + g)], axis=-1)
    theta = float(B[:, 0] @ q[:, 0])                                         # F(u) = θ for a unit torque
    eps = read_footprint(design.gauges, mesh, U[:, :, :1])[:, 0]
    if algebraic_limit is not None:
        d = J - B.T @ q[:, 0]                      # the dual corrections z̃_gᵀ r₀ (read_footprint = B_gᵀ q₀)
        theta, eps = theta + float(d[0]), eps + d[1:]
        info["goal_dual_correction"] = d.tolist()   # already in θ, ε: flexure.enriched's J(u⁺) − J(q) less it
    info["assemble_s"] = assemble_s
    info["total_s"] = time.perf_counter() - t0
    return GoalSolution(U, theta, eps, constrained, q, info, traction, None, solver, system)


def indicators(design, mesh, sol: GoalSolution, weight=None) -> np.ndarray:
    """Vertex DWR indicators (n, 1 + g) of θ and the gauge readings (flexure.dwr), with the
    distributed coupling's traction term F(w ψ_a) added to θ's column. ``weight``: the primal
    weight's surplus coefficients (ce, cf) if already known (flexure.enriched's e_W), else the
    Bank–Weiser local problems'."""
    from flexure import dwr

    eta = dwr.dual_weighted_residuals(mesh, design.material, sol.U[:, :, 0], sol.U[:, :, 1:],
                                      design.gauges, sol.constrained, weight=weight)
    if sol.traction:
        ce, cf = dwr.primal_weight(mesh, sol.U[:, :, 0], sol.constrained)
        for faces, ref in sol.traction:
            eta[:, 0] += dwr.moment_traction_indicators(mesh, faces, ref, ce, cf)
    return eta
