"""The six load cases' gauge readings from an adaptive level's goal solve, without solving them.

The goal solve (flexure.goals) has, on the same reduced system A q = b, the torque case q₀ and each
gauge's dual z_g, A z_g = Tᵀ F_g (F_g the gauge's read-out functional). A is symmetric, so gauge g's
reading under any load case j, A q_j = b_j, is

    ε_g(j) = F_gᵀ T q_j = (A z_g)ᵀ q_j = z_gᵀ A q_j = z_gᵀ b_j,

one dot product per (gauge, case) in place of a CG on five more right-hand sides. Rigid coupling:
b_j is the unit wrench on the six reference dofs (the last six of q), so ε_g(j) = wrench_j · z_g[ref];
distributed: b_j is the wrench's statically equivalent traction (bc.wrench_traction) on the bore
faces. The torque case keeps its own primal reading (as the levels' goal values). The algebraic
error of a dual reading is z̃_gᵀ b_j − z_gᵀ b_j = −r_gᵀ q_j (r_g the dual's CG residual), of the same
order as a primal read-out's at the same CG tolerance (tests/test_fem_goal_cases.py compares both).
"""

from __future__ import annotations

import numpy as np


def from_goals(sol):
    """A ``cases`` function for flexure.analysis.analyze_mesh (the signature of
    ``analysis.solved_cases``) reading the load cases from ``sol`` (a flexure.goals.GoalSolution of
    this very mesh and selections)."""

    def cases(design, mesh, K, load_nodes, fixed_nodes, ref, wrench, x0=None, solver=None, rtol=None):
        Z = sol.q[:, 1:]                                             # (n_q, g) the duals
        if design.coupling == "rigid":
            readings = Z[-6:].T @ wrench.T                          # (g, cases): z_g[ref] · wrench_j
        else:
            from flexure.bc import wrench_traction

            faces, ref_sol = sol.traction[0]
            Bc = np.column_stack([wrench_traction(mesh, faces, ref_sol, w[:3], w[3:]).ravel() for w in wrench])
            readings = Z.T @ Bc
        torque = int(np.flatnonzero(wrench[:, 5] == 1.0)[0])
        readings[:, torque] = sol.eps
        info = dict(sol.info)
        info["solver"] = (f"{sol.info.get('solver', '')}; the load cases' gauge readings from the gauges' "
                          "duals (ε_g(j) = z_gᵀ b_j, flexure.goal_cases)")
        return sol.U[:, :, 0], readings, float(sol.theta), info

    return cases
