"""The adaptive path's goal solve (torque case + gauge duals, one matrix), old against new, in one process.

    python benchmarks/bench_fem_goals.py [DESIGN.toml | thin_step | round_stl ...] [--rtol 0.02] [--json OUT]

For each part: the adaptive analysis runs to ``--rtol`` (flexure.adaptive); on its last mesh the
goal system (A, its 1 + g right-hand sides) is taken and solved by the multi-column CG to the goal
tolerance with three preconditioners — the anchor is the first, measured in the same run:

* ``before``: the p-multigrid as it was (block Gauss–Seidel sweep from zero, then A X for the
  residual; the coarse V-cycle by pyamg one column at a time), BLAS with its own thread count;
* ``1 BLAS thread``: the same inside flexure.blas.limited();
* ``after``: flexure.solve._pmg_multi (sweep + residual in one pass over the lower triangle, the
  coarse V-cycle on all columns at once, flexure.vcycle), one BLAS thread.

Then, from the level's own initial guess (the previous level prolongated), the CG at tolerances
1e-3 … 1e-8: iterations and the largest relative error of the goal values (θ, each gauge reading of
the torque case) against a 1e-10 solve — what a CG tolerance tied to --rtol would save.

Prints CPU and wall seconds of the set-up and of the CG, iterations, the largest difference of the
solutions (they must agree to the CG tolerance) and the machine's load.

Measured 2026-11-26 (thin_step --rtol 0.01: the thin STEP annulus of benchmarks/fem_annulus.py, last
level 235 008 dofs, 5 columns, CG to 1e-6 from zero, 2 cores at load 6.3): CG 34.2 CPU-s before,
30.6 with one BLAS thread (0.89 ×), 16.2 after (0.47 ×; wall 199 → 68 s); the same iterations
[45, 40, 39, 40, 39] and solutions within 8e-11. From the prolongated start: 7–8 iterations to 1e-3
(goal error 1.9e-6), 11 to 1e-4 (2.5e-6), 31 to 1e-6 (3.5e-9).
"""

from __future__ import annotations

import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))


def _load(name: str, folder: Path):
    from flexure.design import load_design

    if name.endswith(".toml"):
        return load_design(name)
    import fem_annulus

    part, kind = name.split("_")
    return fem_annulus.make_part(folder, part, kind)


def _old_preconditioner(A, coarse, B_coarse, smoothed: bool):
    """The p-multigrid before this change (reconstructed from its primitives)."""
    from flexure import multirhs
    from flexure import solve as fsolve

    Dinv, ml, M1, It = fsolve._pmg_setup(A, coarse, B_coarse, smoothed)
    Dinv = np.ascontiguousarray(Dinv)

    def apply(R):
        X = np.zeros_like(R)
        multirhs.block_gauss_seidel(A, Dinv, X, R, forward=True)
        Rc = It @ (R - multirhs.spmm(A, X))
        X += coarse @ np.column_stack([M1 @ Rc[:, j] for j in range(Rc.shape[1])])
        multirhs.block_gauss_seidel(A, Dinv, X, R, forward=False)
        return X

    return apply


def goal_system(design, rtol: float):
    """(reduced system, goal right-hand sides B, x0 or None, smoothed) of the last adaptive level."""
    from flexure import goals
    from flexure import solve as fsolve
    from flexure.adaptive import analyze_adaptive

    seen = {}
    orig = fsolve.prepared

    def spy(system, rtol_=1e-10, smoothed_coarse=False):
        solver = orig(system, rtol_, smoothed_coarse)

        def run(B, x0=None, r=None):
            seen.update(system=system, B=np.array(B), x0=None if x0 is None else np.array(x0),
                        smoothed=smoothed_coarse)
            return solver(B, x0, r)
        return run

    fsolve.prepared = spy
    try:
        res, _ = analyze_adaptive(design, rtol=rtol)
    finally:
        fsolve.prepared = orig
    del res
    return seen, goals.GOAL_RTOL


def bench(name: str, rtol: float) -> dict:
    from flexure import blas, multirhs
    from flexure import solve as fsolve

    with tempfile.TemporaryDirectory() as tmp:
        design = _load(name, Path(tmp))
        multirhs.warm()
        seen, cg_rtol = goal_system(design, rtol)
    sy, B = seen["system"], seen["B"]
    A = sy.A.tocsr()
    A.sort_indices()
    B = np.ascontiguousarray(B)
    rows, ref = [], None
    for label in ("before", "1 BLAS thread", "after"):
        with (_nothing() if label == "before" else blas.limited(1)):
            c0, t0 = time.process_time(), time.perf_counter()
            if label == "after":
                M, _ = fsolve._pmg_multi(A, sy.coarse, sy.B_coarse, seen["smoothed"], fsolve.PMG_SWEEPS)
            else:
                M = _old_preconditioner(A, sy.coarse, sy.B_coarse, seen["smoothed"])
            c1, t1 = time.process_time(), time.perf_counter()
            X, its, done = multirhs.pcg(A, B, M, cg_rtol, 2000)
            c2, t2 = time.process_time(), time.perf_counter()
        ref = X if ref is None else ref
        rows.append({"variant": label, "setup_cpu_s": c1 - c0, "setup_wall_s": t1 - t0, "cg_cpu_s": c2 - c1,
                     "cg_wall_s": t2 - t1, "iterations": its, "converged": bool(np.all(done)),
                     "max_rel_diff": float(np.abs(X - ref).max() / np.abs(ref).max())})
    # what a CG tolerance tied to --rtol would save: goal values J = B[:, g]ᵀ q₀ (θ, each gauge) from
    # the level's warm start at looser tolerances, against a 1e-10 solve
    with blas.limited(1):
        M, _ = fsolve._pmg_multi(A, sy.coarse, sy.B_coarse, seen["smoothed"], fsolve.PMG_SWEEPS)
        X_ref, _, _ = multirhs.pcg(A, B, M, 1e-10, 4000, seen["x0"])
        J_ref = B.T @ X_ref[:, 0]
        sweep = []
        for tol in (1e-3, 1e-4, 1e-5, 1e-6, 1e-8):
            Xt, its_t, _ = multirhs.pcg(A, B, M, tol, 2000, seen["x0"])
            sweep.append({"cg_rtol": tol, "iterations": its_t,
                          "goal_rel_err": float(np.max(np.abs(B.T @ Xt[:, 0] - J_ref) / np.abs(J_ref)))})
    base = rows[0]["cg_cpu_s"]
    for r in rows:
        r["cg_cpu_ratio"] = r["cg_cpu_s"] / base
    return {"part": name, "rtol": rtol, "dofs": int(A.shape[0]), "columns": int(B.shape[1]),
            "cg_rtol": cg_rtol, "rows": rows, "tolerance_sweep": sweep, "load": float(open("/proc/loadavg").read().split()[0])}


class _nothing:
    def __enter__(self):
        return self

    def __exit__(self, *a):
        return False


def show(r: dict) -> None:
    print(f"## {r['part']} (adaptive to rtol {r['rtol']}): {r['dofs']} dofs, {r['columns']} columns, "
          f"CG to {r['cg_rtol']:g}, load {r['load']:.1f}")
    for x in r["rows"]:
        print(f"  {x['variant']:>14}: set-up {x['setup_cpu_s']:5.1f} CPU-s ({x['setup_wall_s']:5.1f} wall), "
              f"CG {x['cg_cpu_s']:6.1f} CPU-s ({x['cg_wall_s']:6.1f} wall) = {x['cg_cpu_ratio']:.2f} × before, "
              f"iterations {x['iterations']}, Δ {x['max_rel_diff']:.1e}", flush=True)
    for x in r["tolerance_sweep"]:
        print(f"  CG to {x['cg_rtol']:g} from the prolongated start: iterations {x['iterations']}, "
              f"largest relative goal error {x['goal_rel_err']:.1e}")


def main(argv: list[str]) -> None:
    import argparse

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("parts", nargs="*", default=["thin_step"],
                        help="a design TOML, or a part of benchmarks/fem_annulus.py (default: thin_step)")
    parser.add_argument("--rtol", type=float, default=0.02, help="the adaptive analysis's --rtol")
    parser.add_argument("--json", type=Path, default=None, metavar="OUT", help="write the results here")
    args = parser.parse_args(argv)
    results = []
    for n in args.parts:
        r = bench(n, args.rtol)
        show(r)
        results.append(r)
    if args.json:
        args.json.write_text(json.dumps(results, indent=1))


if __name__ == "__main__":
    main(sys.argv[1:])
