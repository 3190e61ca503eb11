"""The P2 goal solve's set-up on a large mesh, the old path against the new in one process.

    python benchmarks/bench_fem_goal_solve.py [DESIGN] [--h-factor 0.8] [--repeat 2]

The design's start mesh (flexure.adaptive.start_mesh at ``--h-factor``: smaller is finer) with the
torque case's boundary conditions (rigid bore, fixed rim); interleaved, ``--repeat`` times:

* ``reduced_system``: A = Tᵀ K T and the Dirichlet rows by scipy's products (bc.REDUCE_COMPILED
  False, the anchor) and by flexure.reduce's row loop; the largest |A_new − A_old| / max |A|;
* ``pmg set-up``: solve._pmg_setup's parts (the Galerkin P1 product Iᵀ A I, pyamg's hierarchy, the
  coarse LU of flexure.vcycle) and the CG of solve_goals' columns (iterations, seconds).

Prints seconds and ratios new/old and the 1-minute load.
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
    ap.add_argument("--cg", action="store_true", help="also time the pmg set-up and the CG")
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
