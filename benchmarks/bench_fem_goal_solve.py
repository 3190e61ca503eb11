"""The P2 goal solve's set-up on a large mesh, the old path against the new in one process.

    python benchmarks/bench_fem_goal_solve.py [DESIGN] [--h-factor 0.8] [--repeat 2]

The design's start mesh (flexure.adaptive.start_mesh at ``--h-factor``: smaller is finer) with the
torque case's boundary conditions (rigid bore, fixed rim); interleaved, ``--repeat`` times:

* ``reduced_system``: A = Tᵀ K T and the Dirichlet rows by scipy's products (bc.REDUCE_COMPILED
  False, the anchor) and by flexure.reduce's row loop; the largest |A_new − A_old| / max |A|;
* ``pmg set-up``: solve._pmg_setup's parts (the Galerkin P1 product Iᵀ A I, pyamg's hierarchy, the
  coarse LU of flexure.vcycle) and the CG of solve_goals' columns (iterations, seconds).

* ``--goals``: flexure.goals.solve_goals as an adaptive run to 2 % calls it, old path (all the
  flags above off, COLAMD coarse LU) against new, interleaved: seconds per phase, CG iterations,
  goal differences.

Prints seconds and ratios new/old and the 1-minute load. Measured 2026-11-27 (thick_disc, h-factor
1.0: 228 660 dofs, K 16.7 M entries; 2 cores at load 4–5.5, shared): reduced_system 0.18–0.42 × the
scipy path (0.52–1.83 s against 2.6–4.4 s), A equal to 2.7e-17 of max |A|; the coarse LU 0.31 s
against 0.66 s (COLAMD); solve_goals 19.4–20.1 s against 23.1–23.6 s (0.85 ×: assemble 5.1 against
6.9 s, set-up 3.6 against 4.7 s, CG 10.3 against 10.9 s), the same iterations [19, 10, 10, 10, 10],
θ and the gauge readings equal to 1.4e-13. At load 1.3 (same day, --repeat 2 --cg --goals):
reduced_system 0.37 s against 1.26 s (0.30 ×); solve_goals 6.07 s against 7.09 s (0.86 ×: assemble
1.78 against 2.39 s, set-up 1.02 against 1.39 s, CG 3.10 against 3.14 s), goals equal to 2.7e-13.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))


def main(argv=None) -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("design", nargs="?", default="thick_disc")
    ap.add_argument("--h-factor", type=float, default=0.8)
    ap.add_argument("--repeat", type=int, default=2)
    ap.add_argument("--cg", action="store_true", help="also time the pmg set-up's parts")
    ap.add_argument("--goals", action="store_true", help="also solve_goals old vs new (interleaved, --repeat times)")
    a = ap.parse_args(argv)
    from fem_adaptive import design_path
    from flexure import bc
    from flexure.adaptive import start_mesh
    from flexure.analysis import _selections
    from flexure.design import load_design
    from flexure.fem import stiffness_matrix

    d = load_design(design_path(a.design))
    mesh = start_mesh(d, initial_h_factor=a.h_factor).mesh
    load, fixed = _selections(d, mesh)
    K = stiffness_matrix(mesh, d.material)
    ref = np.array([0.0, 0.0, 0.5 * (mesh.points[:, 2].min() + mesh.points[:, 2].max())])
    p = bc.Problem(mesh, d.material).fix(fixed)
    p.couple_rigid(load, ref, kind="kinematic")
    print(f"{a.design}: {mesh.n_dofs} dofs, K nnz {K.nnz}, load {os.getloadavg()[0]:.2f}")
    bc.REDUCE_COMPILED = True
    p.reduced_system(K)                                       # compile / load the cache
    times = {False: [], True: []}
    for _ in range(a.repeat):
        for flag in (False, True):
            bc.REDUCE_COMPILED = flag
            t = time.perf_counter()
            s = p.reduced_system(K)
            times[flag].append(time.perf_counter() - t)
            if flag:
                new = s
            else:
                old = s
    err = abs(new.A - old.A).max() / abs(old.A).max()
    to, tn = min(times[False]), min(times[True])
    print(f"reduced_system: scipy {to:.2f} s, compiled {tn:.2f} s (ratio {tn / to:.2f}); "
          f"max|dA|/max|A| {err:.1e}; load {os.getloadavg()[0]:.2f}")
    if a.cg:
        _pmg(new, d, mesh)
    if a.goals:
        _goals(d, mesh, a.repeat)


def _flags(new: bool) -> None:
    """The new path (compiled reduction, Dirichlet rows, diagonal blocks, minimum-degree coarse LU) or the old."""
    from flexure import bc, vcycle
    from flexure import solve as fsolve

    bc.REDUCE_COMPILED = fsolve.BLOCKS_COMPILED = new
    vcycle.COARSE_ORDERING = "MMD_AT_PLUS_A" if new else "COLAMD"


def _goals(d, mesh, repeat: int, rtol: float = 0.02) -> None:
    """solve_goals as in an adaptive run to ``rtol`` (CG tolerance and algebraic limit tied to it)."""
    from flexure.goals import ALGEBRAIC_SHARE, cg_rtol_for, solve_goals

    _flags(True)
    solve_goals(d, mesh, rtol=1e-4)                          # compile / load the caches
    best, sols = {}, {}
    for _ in range(repeat):
        for new in (False, True):
            _flags(new)
            t = time.perf_counter()
            s = solve_goals(d, mesh, rtol=cg_rtol_for(rtol), algebraic_limit=ALGEBRAIC_SHARE * rtol)
            i = dict(s.info, wall=time.perf_counter() - t)
            if new not in best or i["wall"] < best[new]["wall"]:
                best[new] = i
            sols[new] = s
            print(f"{'new' if new else 'old'}: {i['wall']:.2f} s (assemble {i['assemble_s']:.2f}, set-up "
                  f"{i['setup_s']:.2f}, CG {i['cg_s']:.2f}), iterations {i['iterations']}, load {os.getloadavg()[0]:.2f}")
    _flags(True)
    o, n = sols[False], sols[True]
    print(f"solve_goals new/old {best[True]['wall'] / best[False]['wall']:.2f}; θ differs by "
          f"{abs(n.theta - o.theta) / abs(o.theta):.1e}, gauges by {np.abs(n.eps - o.eps).max() / np.abs(o.eps).max():.1e} (relative)")


def _pmg(system, d, mesh) -> None:
    from flexure import solve as fsolve
    from flexure.analysis import SMOOTHED_COARSE
    from flexure.vcycle import MultiVCycle

    A = system.A
    t = time.perf_counter()
    A1 = (system.coarse.T @ A @ system.coarse).tocsr()
    tg = time.perf_counter() - t
    t = time.perf_counter()
    ml = fsolve._sa_hierarchy(A1, system.B_coarse, smoothed=SMOOTHED_COARSE[d.mesher], max_coarse=fsolve.PMG_MAX_COARSE)
    ta = time.perf_counter() - t
    t = time.perf_counter()
    MultiVCycle(ml)
    tv = time.perf_counter() - t
    print(f"pmg set-up: Galerkin {tg:.2f} s, pyamg {ta:.2f} s, MultiVCycle (coarse LU) {tv:.2f} s; "
          f"coarse {A1.shape[0]} -> {ml.levels[-1].A.shape[0]}; load {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
