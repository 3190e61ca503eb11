"""The FEM's parallel kernels (flexure.threads), each with 1 thread and with N (default the machine's
cores) in the same process, interleaved, on the first mesh of an adaptive run.

    python benchmarks/bench_fem_parallel.py [DESIGN.toml] [--h-factor F] [--threads N] [--reps R]
    python benchmarks/bench_fem_parallel.py --cold     # numba's first-call cost, empty and filled cache

Per kernel: the best of R runs with 1 thread and with N (alternating, so a load change hits both),
the ratio t_1/t_N, and the machine's 1-minute load before and after. On a shared machine the
ratio is the claim, not the seconds. numba's compilation is done by a first untimed call (its cold
cost, with an empty cache, is printed at the top: the seconds of that first call of every kernel).
Results are checked equal between the thread counts (tests/test_parallel_kernels.py asserts it).

Measured 2026-11-26 on the shared 2-core machine, thick_disc first mesh (83 901 P2 dofs), at load
7.6 (no core free: every 2-thread ratio is ≤ 1.1, the CSR products 0.5–0.75; at load 2–3 the
enriched assembly 0.72, a CSR product 0.6–0.75, a pure compute loop 1.0–1.1 — the machine had no
idle core all session, so the 2-core gain could not be shown; flexure.threads' auto mode therefore
takes 1 thread whenever another process runs). Single-thread gains of the compiled forms: the
stiffness 0.36 s against numpy's 0.74 s (load 7.6; 206 k dofs 1.4–1.6 s against 4.2–6.6 s at load
5); physical_gradients on 63 888 curved P2 elements 0.09 s against 1.42 s, point_jacobians (14
points) 0.23 s against 2.51 s (load 3.2). Cold start: --cold, empty numba cache 30 s (stiffness, incl. the shared pattern/colouring
loops) + 14 s (enriched assembly) + 9 s (CSR products) at load 4, paid once at install by run.sh
(flexure.kernels_warm); with the cache filled 2.2 + 0.2 + 0.1 s.
"""

from __future__ import annotations

import os
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def _load() -> float:
    return os.getloadavg()[0]


def pair(name: str, fn, nt: int, reps: int) -> tuple[float, float]:
    """Best-of-``reps`` seconds of fn() with 1 and with nt threads, alternating; printed with the ratio."""
    from flexure import threads

    best = {1: np.inf, nt: np.inf}
    l0 = _load()
    for _ in range(reps):
        for n in (1, nt):
            with threads.limited(n):
                t = time.perf_counter()
                fn()
                best[n] = min(best[n], time.perf_counter() - t)
    print(f"  {name:34s} 1 thread {best[1]:8.4f} s   {nt} threads {best[nt]:8.4f} s   "
          f"ratio {best[1] / best[nt]:5.2f}   (load {l0:.1f} → {_load():.1f})", flush=True)
    return best[1], best[nt]


def bench(path: str, h_factor: float | None, nt: int, reps: int) -> None:
    from flexure import _enriched_kernels as ek
    from flexure import adaptive, enriched, enriched_assembly, sparse_parallel
    from flexure.design import load_design
    from flexure.goals import solve_goals

    design = load_design(path)
    mres = adaptive.start_mesh(design, None, adaptive.INITIAL_H_FACTOR if h_factor is None else h_factor, None)
    mesh = adaptive.geometry(design, mres)[0].mesh
    sol = solve_goals(design, mesh, rtol=1e-6)
    print(f"{Path(path).stem}: {mesh.n_dofs} P2 dofs, {mesh.n_elements} elements (load {_load():.1f})", flush=True)
    num = enriched.surplus_numbering(mesh, np.asarray(sol.constrained, bool))
    U0 = sol.U[:, :, 0]
    t = time.perf_counter()
    K, r, C, Dinv, _ = enriched_assembly.assemble_enriched(mesh, design.material, U0, num)
    print(f"  first call (numba cache load or compile): assemble_enriched {time.perf_counter() - t:.2f} s")
    G, sign, free = num
    kept = np.cumsum(free) - 1
    nk = int(free.sum())
    Gk = np.where(free[G], kept[G], -1).astype(np.int64)
    tets = np.ascontiguousarray(mesh.tets, dtype=np.int64)
    V = np.ascontiguousarray(tets[:, :4])
    from flexure import fem
    pair("fem.stiffness_matrix (compiled)", lambda: fem.stiffness_matrix(mesh, design.material), nt, reps)
    t = time.perf_counter()
    fem._stiffness_numpy(mesh, design.material)
    print(f"  numpy anchor: fem._stiffness_numpy {time.perf_counter() - t:.3f} s (load {_load():.1f})", flush=True)
    pair("enriched: assemble_enriched (all)", lambda: enriched_assembly.assemble_enriched(
        mesh, design.material, U0, num), nt, reps)
    from flexure import threads
    pair("enriched: block_pattern (coupling)", lambda: ek.block_pattern(tets, Gk, mesh.n_nodes, nk, threads.count()),
         nt, reps)
    pair("enriched: colour_elements (serial)", lambda: ek.colour_elements(V, mesh.n_nodes), nt, reps)
    A = sol.system.A
    rng = np.random.default_rng(0)
    xa, xw, xc = rng.normal(size=A.shape[0]), rng.normal(size=C.shape[1]), rng.normal(size=C.shape[0])
    print(f"  scipy one-thread anchors: A x {_best(lambda: A @ xa, reps):.4f} s, C x {_best(lambda: C @ xw, reps):.4f} s, "
          f"Cᵀ x {_best(lambda: C.T @ xc, reps):.4f} s, K_WW x {_best(lambda: K @ xw, reps):.4f} s")
    pair("CG: A x (P2 reduced)", lambda: sparse_parallel.matvec(A, xa), nt, reps * 3)
    pair("CG: C x (coupling)", lambda: sparse_parallel.matvec(C, xw), nt, reps * 3)
    pair("CG: Cᵀ x (coupling)", lambda: sparse_parallel.rmatvec(C, xc), nt, reps * 3)
    pair("CG: K_WW x", lambda: sparse_parallel.matvec(K, xw), nt, reps * 3)
    for n in (1, nt):
        with threads.limited(n):
            out = enriched.enriched_solve(sol.system, mesh, design.material, design.gauges, U0, sol.q[:, 0],
                                          sol.constrained, sol.solver.precond,
                                          theta_index=sol.system.ref_slices[0].start + 5)
            print(f"  enriched_solve, {n} thread(s): set-up {out[2]['setup_s']:.2f} s, CG {out[2]['solve_s']:.2f} s "
                  f"({out[2]['pcg_iterations']} it; load {_load():.1f}); θ error {out[1]:.6e}", flush=True)


_COLD = """
import time, numpy as np
t0 = time.perf_counter()
from flexure import enriched, enriched_assembly, fem, sparse_parallel, threads
from flexure.material import Material
from flexure.mesh import box_mesh, to_quadratic
m = to_quadratic(box_mesh(2, 2, 2)); mat = Material(70e9, 0.33, 270e6, 'al')
t1 = time.perf_counter()
K = fem.stiffness_matrix(m, mat)
t2 = time.perf_counter()
out = enriched_assembly.assemble_enriched(m, mat, np.zeros((m.n_nodes, 3)),
                                          enriched.surplus_numbering(m, np.zeros(m.n_nodes, bool)))
t3 = time.perf_counter()
with threads.limited(2):
    sparse_parallel.matvec(K, np.ones(K.shape[0])); sparse_parallel.rmatvec(out[2], np.ones(out[2].shape[0]))
t4 = time.perf_counter()
print(f"stiffness {t2 - t1:.1f} s, enriched assembly {t3 - t2:.1f} s, CSR products {t4 - t3:.1f} s")
"""


def cold() -> None:
    """First-call cost of the parallel kernels in a fresh process: with an empty numba cache (the
    compilation a user's first run pays) and then with that cache filled (every later run)."""
    import subprocess
    import tempfile

    with tempfile.TemporaryDirectory() as d:
        env = dict(os.environ, NUMBA_CACHE_DIR=d)
        for what in ("empty cache (compile)", "cache filled (load)"):
            r = subprocess.run([sys.executable, "-c", _COLD], env=env, cwd=ROOT, capture_output=True, text=True)
            print(f"  first calls, {what}: {r.stdout.strip() or r.stderr.strip()[-300:]} (load {_load():.1f})",
                  flush=True)


def _best(fn, reps: int) -> float:
    best = np.inf
    for _ in range(reps):
        t = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t)
    return best


def main(argv: list[str]) -> None:
    import argparse

    ap = argparse.ArgumentParser()
    ap.add_argument("design", nargs="?", default=str(ROOT / "tests" / "data" / "fem_reference" / "thick_disc.toml"))
    ap.add_argument("--h-factor", type=float, default=None)
    ap.add_argument("--threads", type=int, default=os.cpu_count() or 1)
    ap.add_argument("--reps", type=int, default=3)
    ap.add_argument("--cold", action="store_true", help="only the first-call (numba compile) cost")
    a = ap.parse_args(argv)
    if a.cold:
        cold()
        return
    bench(a.design, a.h_factor, a.threads, a.reps)


if __name__ == "__main__":
    main(sys.argv[1:])
