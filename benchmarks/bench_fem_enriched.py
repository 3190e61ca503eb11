"""The enriched system's set-up (flexure.enriched_solve: K_WW, r_W, the coupling K_hW, block Jacobi),
the numpy form (the anchor: per-chunk COO → CSR, pairwise sparse sums, T ᵀ C products, slicing) against
the compiled assembly (flexure.enriched_assembly), in one process, on the adaptive run's first mesh.

    python benchmarks/bench_fem_enriched.py [DESIGN.toml ...] [--h-factor 2.0]

For each part: the first mesh of the adaptive run (flexure.adaptive.start_mesh, the given coarsening
of the size field), its goal solve, then ``enriched_solve`` twice — estimator.compiled off (numpy
form) and on (compiled; numba's compilation is done by a warm-up on a small mesh first) — printing
the set-up and CG seconds, the ratio new/old of the set-up, the growth of the process's peak RSS (the
compiled run first, so the numpy form's figure is what it needs beyond the compiled one's peak) and
the largest relative difference of J(u⁺) − J(u_h) (θ and the gauges; the same system up to round-off,
the CG to RTOL). The machine's 1-minute load is printed with every line: timings on a shared machine
are noisy, the ratio less so.

Measured 2026-11-26 (2 cores shared, load 8.3): paper_disc h-factor 4.0 (22 809 P2 dofs, 66 978
enriched): set-up 6.89 s numpy → 3.96 s compiled (0.58 ×; the rest is bank_weiser.face_rhs, still
numpy), peak RSS growth 0.17 → 0.08 GB, estimates equal to 6e-13. In whole adaptive runs (torquebench
flexure, CPU seconds, load 10–12): paper_disc default 43.3 → 25.1 CPU-s with the looser enriched CG
(enriched.RTOL 1e-2), peak 0.98 → 0.76 GB, the same levels; at 194 k/265 k P2 dofs (thick_disc) the
enriched set-up is 26/22 s of 78/57 s at load ~9.
"""

from __future__ import annotations

import os
import resource
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def _load() -> str:
    return f"load {os.getloadavg()[0]:.1f}"


def _warm() -> None:
    """Compile (or load from numba's cache) the kernels on a tiny mesh."""
    from flexure import enriched_assembly
    from flexure.material import Material
    from flexure.mesh import box_mesh, to_quadratic

    m = to_quadratic(box_mesh(1, 1, 1))
    from flexure.enriched import surplus_numbering

    enriched_assembly.assemble_enriched(m, Material(70e9, 0.33, 270e6, "al"), np.zeros((m.n_nodes, 3)),
                                        surplus_numbering(m, np.zeros(m.n_nodes, bool)))


def bench(path: str, h_factor: float) -> None:
    from estimator import compiled
    from flexure.adaptive import geometry, start_mesh
    from flexure.design import load_design
    from flexure.enriched import enriched_solve
    from flexure.goals import solve_goals

    design = load_design(path)
    mres = start_mesh(design, None, h_factor, None)
    mesh = geometry(design, mres)[0].mesh
    sol = solve_goals(design, mesh, rtol=1e-6)
    print(f"{Path(path).stem}: {mesh.n_dofs} P2 dofs, {mesh.n_elements} elements ({_load()})", flush=True)
    out = {}
    for name, on in (("compiled", True), ("numpy", False)):     # compiled first: its own peak
        compiled.ENABLED = on
        rss0 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e6
        t = time.perf_counter()
        d_eps, d_theta, info = enriched_solve(sol.system, mesh, design.material, design.gauges, sol.U[:, :, 0],
                                              sol.q[:, 0], sol.constrained, sol.solver.precond,
                                              theta_index=sol.system.ref_slices[0].start + 5)
        wall = time.perf_counter() - t
        grew = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e6 - rss0
        out[name] = (np.concatenate([[d_theta], d_eps]), info)
        print(f"  {name:8s}: set-up {info['setup_s']:6.2f} s, CG {info['solve_s']:6.2f} s "
              f"({info['pcg_iterations']} it, {info['enriched_dofs']} dofs), wall {wall:6.2f} s, "
              f"peak RSS +{grew:.2f} GB ({_load()})", flush=True)
    compiled.ENABLED = True
    a, b = out["numpy"][0], out["compiled"][0]
    print(f"  set-up compiled/numpy: {out['compiled'][1]['setup_s'] / out['numpy'][1]['setup_s']:.2f} ×; "
          f"max |ΔJ|/|J| of the estimates: {np.max(np.abs(a - b) / np.abs(a)):.1e}", flush=True)


def main(argv: list[str]) -> None:
    h = 2.0
    if "--h-factor" in argv:
        i = argv.index("--h-factor")
        h = float(argv[i + 1])
        argv = argv[:i] + argv[i + 2:]
    _warm()
    for p in argv or [str(ROOT / "designs" / "paper_disc.toml")]:
        bench(p, h)


if __name__ == "__main__":
    main(sys.argv[1:])
