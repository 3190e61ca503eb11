"""The enriched solve's storage of K_WW and K_hW (flexure.enriched STORAGE) and W preconditioner
(W_PRECOND): the scalar float64 CSR with 3 × 3 block Jacobi on W (the anchor, the old path) against
3 × 3 blocks of float64 ("block64") and float32 ("block32") values (flexure.block_sparse) with block
Jacobi, and float32 blocks with the multicolour symmetric block Gauss–Seidel on W ("sgs"),
interleaved in one process on the adaptive run's first mesh of each part.

    python benchmarks/bench_fem_block_storage.py [DESIGN.toml ...] [--h-factor 1.0] [--rounds 2]

Prints per storage: set-up and CG seconds, PCG iterations, the bytes of K_WW + K_hW (and per P2 dof),
the ratios against the old path of the same round, and the largest relative change of J(u⁺) − J(u_h)
(θ and each gauge) against it (the CG to enriched.RTOL in each: the change is the effect on the CG's
iterate, to compare with the estimate's own accuracy, ~10 %). The 1-minute load with every line.

Measured 2026-11-27 (2 cores shared, load 5–6, --h-factor 1.0 --rounds 1; commit after 3f): K_WW + K_hW
2397–2725 → 891–1013 B/P2 dof (0.37 x) in block32, 0.70 x in block64; set-up 0.57–0.89 x; CG 0.77–0.93 x
in block32/jacobi with the same iterations (29, 23, 24, 22 on paper_disc 134 k, thick_disc 229 k,
reentrant 138 k, cross_frame 142 k) and d moved ≤ 1.3e-4; block32/sgs 19, 17, 18, 17 iterations, CG
0.55–1.07 x, d moved ≤ 3.7e-3 on three parts but 0.12 on paper_disc's smallest gauge (the CG's RTOL
matters more with sgs: why enriched.W_PRECOND stays "jacobi").
"""

from __future__ import annotations

import os
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
CASES = (("csr", "jacobi"), ("block64", "jacobi"), ("block32", "jacobi"), ("block32", "sgs"))


def bench(path: str, h_factor: float, rounds: int) -> None:
    from flexure.adaptive import geometry, start_mesh
    from flexure.design import load_design
    from flexure.enriched import enriched_solve
    from flexure.goals import solve_goals

    design = load_design(path)
    mesh = geometry(design, start_mesh(design, None, h_factor, None))[0].mesh
    sol = solve_goals(design, mesh, rtol=1e-6)
    print(f"{Path(path).stem}: {mesh.n_dofs} P2 dofs, {mesh.n_elements} elements (load {os.getloadavg()[0]:.1f})",
          flush=True)
    for rnd in range(rounds):
        out = {}
        for st, wp in CASES:
            t = time.perf_counter()
            d_eps, d_theta, info = enriched_solve(sol.system, mesh, design.material, design.gauges, sol.U[:, :, 0],
                                                  sol.q[:, 0], sol.constrained, sol.solver.precond,
                                                  theta_index=sol.system.ref_slices[0].start + 5, storage=st,
                                                  w_precond=wp)
            info["wall"] = time.perf_counter() - t
            out[st, wp] = (np.concatenate([[d_theta], d_eps]), info)
        a0, i0 = out[CASES[0]]
        for st, wp in CASES:
            a, i = out[st, wp]
            print(f"  round {rnd} {st:8s} {wp:6s}: set-up {i['setup_s']:6.2f} s ({i['setup_s'] / i0['setup_s']:.2f} x), "
                  f"CG {i['solve_s']:6.2f} s ({i['solve_s'] / i0['solve_s']:.2f} x, {i['pcg_iterations']} it), "
                  f"K_WW+K_hW {i['matrix_bytes'] / 1e6:7.1f} MB ({i['matrix_bytes'] / mesh.n_dofs:.0f} B/P2 dof, "
                  f"{i['matrix_bytes'] / i0['matrix_bytes']:.2f} x), max |dJ/J| vs old "
                  f"{np.max(np.abs(a - a0) / np.abs(a0)):.1e} (load {os.getloadavg()[0]:.1f})", flush=True)


def main(argv: list[str]) -> None:
    h, rounds = 1.0, 2
    for flag in ("--h-factor", "--rounds"):
        if flag in argv:
            i = argv.index(flag)
            v = argv[i + 1]
            argv = argv[:i] + argv[i + 2:]
            h, rounds = (float(v), rounds) if flag == "--h-factor" else (h, int(v))
    for p in argv or [str(ROOT / "designs" / "paper_disc.toml")]:
        bench(p, h, rounds)


if __name__ == "__main__":
    main(sys.argv[1:])
