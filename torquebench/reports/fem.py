"""FEM convergence report: error against DOFs and run time, P1/P2 × mesh size × solver.

Problem with a known answer: hollow circular shaft (r_i = 10 mm, r_o = 20 mm, L = 100 mm,
6061-T6) fixed at z = 0, torque T = 10 N·m on the end face through a kinematic rigid coupling.
Exact: stiffness k = GJ/L, J = π(r_o⁴ − r_i⁴)/2; surface strain along ±45° ε = ±T r_o/(2GJ).
Writes reports/fem_convergence.md and reports/fem_convergence.png.
"""

from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np

RI, RO, LEN, TORQUE = 0.010, 0.020, 0.100, 10.0
#: (order, k) → structured mesh (n_r, n_θ, n_z) = (k, 12k, 4k) (P1) / (k, 8k, 3k) (P2 curved)
P1_LEVELS = (1, 2, 3, 4, 5)
P2_LEVELS = (1, 2, 3, 4)
DIRECT_LIMIT_DOFS = 40_000


def torsion_case(order: int, k: int, method: str):
    """Solve the shaft on refinement level k; returns a result row (dict)."""
    from flexure.bc import Problem
    from flexure.fem import stiffness_matrix
    from flexure.material import ALUMINIUM_6061_T6 as MAT
    from flexure.mesh import cylinder_mesh
    from flexure.post import directional_strain, strain_at
    from flexure.solve import solve

    n = (k, 12 * k, 4 * k) if order == 1 else (k, 8 * k, 3 * k)
    t0 = time.perf_counter()
    m = cylinder_mesh(RI, RO, LEN, *n, order=order)
    p = Problem(m, MAT).fix(m.select_nodes(lambda x: x[:, 2] < 1e-12))
    p.couple_rigid(m.select_nodes(lambda x: x[:, 2] > LEN - 1e-12), (0, 0, LEN), moment_Nm=(0, 0, TORQUE))
    t1 = time.perf_counter()
    K = stiffness_matrix(m, MAT)
    s = solve(p, method=method, K=K, rtol=1e-10, condition_estimate=False)
    ang = np.linspace(0, 2 * np.pi, 16, endpoint=False) + 0.05
    r_ev = RO * math.cos(math.pi / n[1])        # inside the outer facets of the P1 polygon
    pts = np.stack([r_ev * np.cos(ang), r_ev * np.sin(ang), np.full_like(ang, LEN / 2 + 1e-4)], axis=1)
    d45 = np.stack([-np.sin(ang), np.cos(ang), np.ones_like(ang)], axis=1)
    e45 = directional_strain(strain_at(m, s.u, pts), d45)
    total = time.perf_counter() - t1
    G, J = MAT.shear_modulus_Pa, math.pi / 2 * (RO ** 4 - RI ** 4)
    k_ex, e_ex = G * J / LEN, TORQUE * r_ev / (2 * G * J)
    k_fe = TORQUE / s.reference[0]["theta_rad"][2]
    return dict(order=order, level=k, mesh=f"{n[0]}×{n[1]}×{n[2]}", dofs=m.n_dofs,
                solver="direct" if "direct" in s.info["solver"] else "amg-cg",
                iterations=s.info["iterations"], residual=s.info["residual_norm"],
                assemble_s=s.info["assemble_s"] if s.info["assemble_s"] > 0 else 0.0,
                time_s=total, mesh_s=t1 - t0, stiffness_err=abs(k_fe / k_ex - 1),
                strain_err=float(np.max(np.abs(e45 / e_ex - 1))), h_rel=1.0 / k)


def study(p1_levels=P1_LEVELS, p2_levels=P2_LEVELS, progress=None) -> list[dict]:
    rows = []
    for order, levels in ((1, p1_levels), (2, p2_levels)):
        for k in levels:
            for method in ("direct", "amg"):
                dofs = 3 * (k + 1) * 12 * k * (4 * k + 1) if order == 1 else 3 * (2 * k + 1) * 16 * k * (6 * k + 1)
                if method == "direct" and dofs > DIRECT_LIMIT_DOFS:
                    continue
                rows.append(torsion_case(order, k, method))
                if progress:
                    progress(rows[-1])
    return rows


def observed_orders(rows: list[dict], key: str) -> dict:
    """Least-squares slope p of log e = p log h + c over the three finest levels (AMG rows)."""
    out = {}
    for order in (1, 2):
        r = sorted([x for x in rows if x["order"] == order and x["solver"] == "amg-cg"], key=lambda x: x["level"])
        r = r[-3:]
        if len(r) >= 2:
            h = np.log([x["h_rel"] for x in r])
            e = np.log([x[key] for x in r])
            out[order] = float(np.polyfit(h, e, 1)[0])
    return out


def table(rows: list[dict]) -> str:
    L = ["| order | mesh (n_r×n_θ×n_z) | DOFs | solver | iterations | residual | run time [s] | "
         "stiffness error | ε₄₅ error (max of 16 points) |",
         "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        L.append(f"| P{r['order']} | {r['mesh']} | {r['dofs']:,} | {r['solver']} | {r['iterations']} | "
                 f"{r['residual']:.1e} | {r['time_s']:.2f} | {r['stiffness_err']:.2e} | {r['strain_err']:.2e} |")
    return "\n".join(L)


def plot(rows: list[dict], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2))
    style = {(1, "direct"): ("C0", "o", "--"), (1, "amg-cg"): ("C0", "s", "-"),
             (2, "direct"): ("C3", "o", "--"), (2, "amg-cg"): ("C3", "s", "-")}
    for (order, solver), (c, mk, ls) in style.items():
        r = [x for x in rows if x["order"] == order and x["solver"] == solver]
        if not r:
            continue
        lab = f"P{order} {solver}"
        axes[0].loglog([x["dofs"] for x in r], [x["stiffness_err"] for x in r], ls, color=c, marker=mk, label=lab)
        axes[0].loglog([x["dofs"] for x in r], [x["strain_err"] for x in r], ":", color=c, marker=mk, alpha=0.6)
        axes[1].loglog([x["time_s"] for x in r], [x["stiffness_err"] for x in r], ls, color=c, marker=mk, label=lab)
    axes[0].set_xlabel("DOFs"), axes[0].set_ylabel("relative error (solid: GJ/L stiffness, dotted: ε₄₅)")
    axes[1].set_xlabel("assembly + solve + read-out time [s]"), axes[1].set_ylabel("stiffness relative error")
    for ax in axes:
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=8)
    fig.suptitle("Hollow shaft in torsion: error against DOFs and run time")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _headline(rows, orders) -> str:
    """One sentence: the finest P2 level's stiffness and strain errors and the observed orders."""
    p2 = max((r for r in rows if r["order"] == 2), key=lambda r: r["dofs"])
    return (f"**Headline:** on a hollow shaft in torsion (exact answer known) P2 tetrahedra reach a stiffness "
            f"error of {p2['stiffness_err']:.1e} and a strain error of {p2['strain_err']:.1e} at "
            f"{p2['dofs']:,} DOFs; the stiffness converges at order "
            + " and ".join(f"{p:.2f} (P{o})" for o, p in orders.items()) + " in h")


def build(out_dir: Path) -> list[Path]:
    from userio.files import atomic_path, write_text_atomic

    out_dir = Path(out_dir)
    rows = study()
    png = out_dir / "fem_convergence.png"
    with atomic_path(png) as tmp:
        plot(rows, Path(tmp))
    ok = observed_orders(rows, "stiffness_err")
    oe = observed_orders(rows, "strain_err")
    L = ["# FEM convergence: hollow shaft in torsion\n",
         "Generated by `torquebench report` (torquebench/reports/fem.py). Hollow 6061-T6 shaft, "
         f"r_i = {RI * 1e3:g} mm, r_o = {RO * 1e3:g} mm, L = {LEN * 1e3:g} mm, fixed at z = 0, "
         f"T = {TORQUE:g} N·m through a kinematic rigid coupling of the end face. Exact: k = GJ/L, "
         "ε₄₅ = T r/(2GJ), read with `strain_at` at 16 points at mid-length on r = r_o cos(π/n_θ) "
         "(just inside the outer facets of the P1 polygon). "
         "Structured meshes; P2 mid-edge nodes on the true circles (isoparametric), P1 polygonal. "
         "Run time = assembly + constrained solve + read-out, on a shared 2-core machine.\n",
         _headline(rows, ok), "",
         table(rows), "",
         "Observed order of convergence in h (least-squares slope over the three finest levels): stiffness "
         + ", ".join(f"P{o}: {p:.2f}" for o, p in ok.items()) + "; ε₄₅ "
         + ", ".join(f"P{o}: {p:.2f}" for o, p in oe.items()) + ".\n",
         "Expected: stiffness (an energy quantity) converges as h² for P1 and h⁴ for P2; point "
         "strains as h for P1 and h² for P2 (plus isoparametric geometry error); pointwise strains at "
         "fixed points are not monotone in h (the points move within their elements), so their "
         "slope is indicative only. At equal run time "
         "P2 is orders of magnitude more accurate than P1, which is why the flexure pipeline uses P2.\n",
         "![error against DOFs and time](fem_convergence.png)\n"]
    md = write_text_atomic(out_dir / "fem_convergence.md", "\n".join(L))
    return [md, png]


# ------------------------------------------------------------------ error against run time (flexure designs)
#: the two geometries of the error-vs-run-time section: (design file in designs/, overrides)
FEM_GEOMETRIES = {
    "paper disc": ("paper_disc.toml", {}),
    "thick disc, 0.5 mm gauges": ("paper_disc.toml", {"thickness_mm": 5.0, "fillet_radius_mm": 0.0,
                                                      "gauges.grid_length_mm": 0.5,
                                                      "gauges.grid_width_mm": 0.5}),
}
#: mesh levels: the design's whole size function × f (flexure.analysis.analyze's h_factor). Below
#: f = 2 the DOFs barely fall (the geometry's own features hold the size), so P2 starts at 2.
FEM_FACTORS = {1: (4.0, 2.0, math.sqrt(2.0), 1.0, 1 / math.sqrt(2.0), 0.5),
               2: (2.0, math.sqrt(2.0), 1.0, 1 / math.sqrt(2.0), 0.5)}
#: the meshers compared: "gmsh" (the default: the exact OpenCASCADE solid), "tetgen" (the design's
#: ``mesher = "tetgen"``: the polygonal profile's surface, graded from it) and "scikit-fem" (an outside
#: point: benchmarks/fem_reference.py, scikit-fem's own P2 assembly, BCs and AMG-CG on our gmsh P1 mesh);
#: "adaptive" (the default run: nested goal-oriented refinement; its plan entries are --rtol values)
MESHERS = ("gmsh", "tetgen", "adaptive", "scikit-fem")
#: "adaptive": flexure.adaptive.analyze_adaptive (the default ``torquebench flexure`` run) at each
#: --rtol of the plan in place of an h factor: one gmsh mesh, nested goal-oriented refinement
ADAPTIVE = "adaptive"
#: geometry → (mesher, order) → h factors; the reference of every figure is the gmsh P2 levels' limit
FEM_PLAN = {
    "paper disc": {("gmsh", 1): FEM_FACTORS[1], ("gmsh", 2): FEM_FACTORS[2],
                   ("tetgen", 2): (2.0, math.sqrt(2.0), 1.0, 1 / math.sqrt(2.0)),
                   (ADAPTIVE, 2): (0.05, 0.02, 0.01, 0.005),
                   ("scikit-fem", 2): (1.0, 1 / math.sqrt(2.0))},
    "thick disc, 0.5 mm gauges": {("gmsh", 1): FEM_FACTORS[1], ("gmsh", 2): FEM_FACTORS[2],
                                  ("tetgen", 2): (2.0, math.sqrt(2.0), 1.0, 1 / math.sqrt(2.0)),
                                  (ADAPTIVE, 2): (0.05, 0.02, 0.01),
                                  ("scikit-fem", 2): (1.0,)},
}
#: the tests' quick plan. gmsh P1 from h × 2: at h × 4 the curvature sizing leaves 3 elements per turn,
#: so the fillets there are a different (cruder) solid and that level does not follow the trend
FEM_QUICK = {"paper disc": {("gmsh", 1): (2.0, math.sqrt(2.0), 1.0), ("tetgen", 1): (4.0,), ("scikit-fem", 2): (4.0,)}}
FEM_FIGURES = {"gauge_strain_per_Nm": "gauge strain per N·m", "torsional_stiffness_Nm_per_rad": "torsional stiffness"}
OUTSIDE = "scikit-fem"


def _scikit_fem_row(design, h_factor: float) -> dict:
    """scikit-fem P2 on our gmsh P1 mesh × h_factor (benchmarks/fem_reference.py): the torque case only."""
    import importlib.util

    from torquebench.io import REPO_ROOT

    path = REPO_ROOT / "benchmarks" / "fem_reference.py"
    spec = importlib.util.spec_from_file_location("_fem_reference", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    ref = mod.reference(design, h_factor)
    return {"dofs": int(ref["dofs"]), "time_s": float(ref["seconds"]), "warnings": [],
            "cg_iterations": int(ref["cg_iterations"]), **{k: float(ref[k]) for k in FEM_FIGURES}}


def _adaptive_row(design, rtol: float) -> dict:
    """The default (adaptive) analysis at ``rtol``: its figures, wall time (meshing, every level, the
    final six load cases) and its own relative error estimate of each figure."""
    from flexure.adaptive import analyze_adaptive

    res, _ = analyze_adaptive(design, rtol=rtol)
    return {"dofs": int(res["dofs"]), "time_s": float(res["total_s"]), "warnings": list(res["warnings"]),
            "stopped_by": res["stopped_by"], **{k: float(res[k]) for k in FEM_FIGURES},
            **{f"{k}_estimate": float(res[f"{k}_error_estimate"] / abs(res[k])) for k in FEM_FIGURES}}


def fem_levels(quick: bool = False, progress: bool = True, on_row=None, meshers=MESHERS) -> list[dict]:
    """Analyse every geometry × mesher × element order × mesh level of the plan (only ``meshers``):
    one row per analysis with its wall time (``analyze``'s total: meshing, assembly, the six load
    cases, read-out; for scikit-fem its meshing, assembly, the torque case and read-out) and the
    figures. The cheapest run first (P1, then P2 coarse to fine); ``on_row(rows)`` after each."""
    import sys

    from flexure.analysis import analyze
    from flexure.design import load_design
    from torquebench.io import REPO_ROOT

    plan = FEM_QUICK if quick else FEM_PLAN
    todo = [(g, m, o, f) for g, runs in plan.items() for (m, o), fs in runs.items() for f in fs if m in meshers]
    rank = {k: i for i, k in enumerate(todo)}
    from tqdm import tqdm
    rows = []
    for g, mesher, order, f in tqdm(sorted(todo, key=lambda x: (x[2], -x[3])), desc="error_vs_runtime: flexure FEM",
                                    file=sys.stderr, disable=not progress, leave=False):
        scene, overrides = FEM_GEOMETRIES[g]
        if mesher == OUTSIDE:
            row = _scikit_fem_row(load_design(REPO_ROOT / "designs" / scene, overrides), f)
        elif mesher == ADAPTIVE:
            row = _adaptive_row(load_design(REPO_ROOT / "designs" / scene, overrides), f)
        else:
            design = load_design(REPO_ROOT / "designs" / scene, {**overrides, "mesh.mesher": mesher})
            res, _ = analyze(design, order=order, h_factor=f)
            row = {"dofs": int(res["dofs"]), "time_s": float(res["total_s"]), "warnings": list(res["warnings"]),
                   **{k: float(res[k]) for k in FEM_FIGURES}}
        rows.append({"geometry": g, "mesher": mesher, "order": order, "h_factor": f, **row})
        if on_row:
            on_row(rows)
    return sorted(rows, key=lambda r: rank[(r["geometry"], r["mesher"], r["order"], r["h_factor"])])


def extrapolate(dofs, values) -> dict:
    """Richardson extrapolation from the three finest levels, h ∝ DOFs^(−1/3) (the levels' real
    size: coarse levels are held up by the geometry's own features, so h_factor overstates them).

    Observed order p (flexure.convergence.observed_order: (q1 − q2)/(q2 − q3) = (h1^p − h2^p)/(h2^p − h3^p),
    in [0.5, 4]); limit R = q3 + (q3 − q2)/((h2/h3)^p − 1); its uncertainty u = |R − q3| (the
    whole correction: a bound, not 1σ). Oscillating levels, or an order at a bound of [0.5, 4]
    (not asymptotic: the correction would be over- or under-stated): R = q3,
    u = 1.25 max(|q1 − q2|, |q2 − q3|)."""
    from flexure.convergence import P_RANGE, observed_order

    n = np.asarray(dofs, float)
    q = np.asarray(values, float)
    idx = np.argsort(n)[-3:]
    n, q = n[idx], q[idx]
    h = (n / n[-1]) ** (-1.0 / 3.0)
    p = observed_order(h, q)
    if math.isnan(p):
        return {"value": float(q[-1]), "uncertainty": 1.25 * float(max(abs(q[0] - q[1]), abs(q[1] - q[2]))),
                "order": math.nan, "finest": float(q[-1]), "dofs": n.astype(int).tolist(),
                "method": "oscillating levels: finest value, 1.25 × the largest change (a bound)"}
    if p <= P_RANGE[0] + 1e-9 or p >= P_RANGE[1] - 1e-9:
        return {"value": float(q[-1]), "uncertainty": 1.25 * float(max(abs(q[0] - q[1]), abs(q[1] - q[2]))),
                "order": float(p), "finest": float(q[-1]), "dofs": n.astype(int).tolist(),
                "method": ("order outside [0.5, 4] (levels not in the asymptotic range): finest value, "
                           "1.25 × the largest change (a bound)")}
    R = float(q[2] + (q[2] - q[1]) / ((h[1] / h[2]) ** p - 1.0))
    return {"value": R, "uncertainty": abs(R - float(q[2])), "order": float(p), "finest": float(q[-1]),
            "dofs": n.astype(int).tolist(),
            "method": f"Richardson from 3 levels, observed order {p:.2f} in h ∝ DOFs^(−1/3); ± the whole correction"}


def _references(rows: list[dict]) -> dict:
    """(geometry, figure) → reference (from gmsh P2, else gmsh P1) and the other order's extrapolation."""
    out = {}
    rows = [r for r in rows if r.get("mesher", "gmsh") == "gmsh"]
    for g in dict.fromkeys(r["geometry"] for r in rows):
        for key in FEM_FIGURES:
            ext = {}
            for order in (1, 2):
                lv = [r for r in rows if r["geometry"] == g and r["order"] == order]
                if len(lv) >= 3:
                    ext[order] = extrapolate([r["dofs"] for r in lv], [r[key] for r in lv])
            if ext:
                ref = ext.get(2) or ext[1]
                out[(g, key)] = {"ref": ref, "ref_order": 2 if 2 in ext else 1, "other": ext.get(1) if 2 in ext else None}
    return out


#: a cross-check whose own uncertainty exceeds this (relative) says nothing
CROSS_CHECK_MAX_REL = 0.10


def error_vs_runtime_section(out_dir: Path, quick: bool = False) -> tuple[list[str], list[Path]]:
    """Flexure FEM: P1/P2 × mesh level × mesher (gmsh, tetgen) on two geometries, scikit-fem as an
    outside point; gauge strain and stiffness error against wall time, errors against the
    Richardson limit of the finest gmsh P2 levels."""
    return fem_section(fem_levels(quick), out_dir, quick)


def _setting(r: dict) -> tuple[str, str]:
    """(setting label, plot family) of a row."""
    m = r.get("mesher", "gmsh")
    if m == OUTSIDE:
        return f"scikit-fem P{r['order']} (same mesh), h × {r['h_factor']:.3g}", f"scikit-fem P{r['order']} (outside point)"
    if m == "gmsh":
        return f"P{r['order']}, h × {r['h_factor']:.3g}", f"P{r['order']}"
    if m == ADAPTIVE:
        return f"P{r['order']} adaptive, --rtol {r['h_factor']:.3g}", f"P{r['order']} adaptive (the default)"
    return f"P{r['order']} {m}, h × {r['h_factor']:.3g}", f"P{r['order']} {m}"


def fem_section(rows: list[dict], out_dir: Path, quick: bool = False) -> tuple[list[str], list[Path]]:
    """The Markdown and PNGs of :func:`error_vs_runtime_section` from ``fem_levels`` rows."""
    from torquebench.reports.error_vs_runtime import _fmt_t, section

    rows = sorted(rows, key=lambda r: (MESHERS.index(r.get("mesher", "gmsh")), r["order"], -r["h_factor"]))
    refs = _references(rows)
    tet = sorted({r["h_factor"] for r in rows if r.get("mesher") == "tetgen"}, reverse=True)
    sk = sorted({r["h_factor"] for r in rows if r.get("mesher") == OUTSIDE}, reverse=True)
    gm = sorted({r["h_factor"] for r in rows if r.get("mesher", "gmsh") == "gmsh"}, reverse=True)
    ad = sorted({r["h_factor"] for r in rows if r.get("mesher") == ADAPTIVE}, reverse=True)
    lines = ["## Flexure FEM (P1 and P2 × mesh size × mesher, and the adaptive default; two geometries; scikit-fem as "
             "an outside point)", "",
             "`flexure.analysis.analyze` on the design's mesh with every element size × f, "
             "P1 (4-node) and P2 (10-node) tetrahedra. Meshers: gmsh (the default; the exact OpenCASCADE "
             f"solid with true circles and fillets; f = {', '.join(f'{f:.3g}' for f in gm)})"
             + (f" and tetgen (the design with `mesher = \"tetgen\"`: the polygonal profile, "
                "3 segments per quarter circle at the design's size `coarse`, meshed from its surface; "
                f"f = {', '.join(f'{f:.3g}' for f in tet)}; its error against the gmsh reference includes "
                "the polygon's geometry error, which no mesh refinement removes)" if tet else "")
             + (" and adaptive (the default `torquebench flexure` run, `flexure.adaptive`: one gmsh mesh, then "
                "nested goal-oriented refinement until every goal's own error estimate is below --rtol; "
                f"--rtol = {', '.join(f'{f:.3g}' for f in ad)}; its own relative ± is listed beside its true "
                "error)" if ad else "") + ". "
             "Wall time = the whole analysis a user waits for "
             "(meshing, assembly, the six load cases, gauge read-out). Geometries: `designs/paper_disc.toml` "
             "(2.2 mm, fillets, 1.5 mm gauges) and the same disc 5 mm thick without fillets with 0.5 mm "
             "gauges (`tests/test_fem_thick_disc.py`)."
             + (f" Outside point of comparison: scikit-fem P2 (`benchmarks/fem_reference.py`: scikit-fem's own "
                "assembly, boundary conditions (the bore turned rigidly, equal to our coupling under a pure "
                "torque by symmetry) and pyamg-preconditioned CG) on our gmsh P1 mesh at the same f, so at "
                "the same DOF count as our P2 level; its wall time is meshing + assembly + the torque case "
                "only (one right-hand side, not six) + read-out. It is plotted as black stars and listed "
                "separately: not one of our settings, so not on the Pareto front and not in the "
                f"cheapest-setting tables (f = {', '.join(f'{f:.3g}' for f in sk)})." if sk else "")
             + (" QUICK mode: paper disc, gmsh P1 on coarse levels, one tetgen P1 and one scikit-fem P2 level "
                "only; the reference (gmsh P1 levels) is then NOT converged." if quick else ""),
             "", "Reference for each figure: Richardson extrapolation of the three finest gmsh P2 levels with "
             "the observed order (h ∝ DOFs^(−1/3)); its uncertainty is the whole extrapolation step (or, "
             "for oscillating levels or an order outside [0.5, 4], the finest value ± 1.25 × the largest change), so the finest P2 level's own error is "
             "at most that uncertainty by construction. Cross-check: the P1 levels, an independent "
             "element family, should extrapolate to the same limit within the two uncertainties; when P1's "
             f"own extrapolation is uncertain by more than {CROSS_CHECK_MAX_REL:.0%} (P1 far from its "
             "asymptotic range) the cross-check is reported as not informative. "
             "Targets below twice the reference's uncertainty are reported as not resolvable.", "",
             "| geometry | figure | finest level (DOFs) | reference | ± (relative) | how | P1 extrapolates to | agree? |",
             "|---|---|---|---|---|---|---|---|"]
    for (g, key), rr in refs.items():
        ref, other = rr["ref"], rr["other"]
        rel = ref["uncertainty"] / abs(ref["value"])
        if other is not None:
            agree = abs(other["value"] - ref["value"]) <= other["uncertainty"] + ref["uncertainty"]
            o_rel = other["uncertainty"] / abs(other["value"])
            o = (f"{other['value']:.5g} ± {o_rel:.2%}",
                 "not informative (P1 too uncertain)" if o_rel > CROSS_CHECK_MAX_REL else
                 "yes" if agree else f"no ({abs(other['value'] / ref['value'] - 1):.2%} apart): not shown converged")
        else:
            o = ("—", "—")
        lines.append(f"| {g} | {FEM_FIGURES[key]} | {ref['finest']:.5g} ({ref['dofs'][-1]:,}) | {ref['value']:.5g} | "
                     f"{rel:.2%} | P{rr['ref_order']} gmsh: {ref['method']} | {o[0]} | {o[1]} |")
    lines.append("")
    pngs: list[Path] = []
    for (g, key), rr in refs.items():
        R = rr["ref"]["value"]
        srows, outside = [], []
        for r in (r for r in rows if r["geometry"] == g):
            setting, family = _setting(r)
            row = {"setting": setting, "family": family, "time_s": r["time_s"], "error": abs(r[key] / R - 1),
                   "dofs": r["dofs"], "value": r[key]}
            if any(q.get("mesher") == ADAPTIVE for q in rows):
                row["its own ± (adaptive)"] = (f"{r[key + '_estimate']:.3g} (stopped by {r['stopped_by']})"
                                               if r.get("mesher") == ADAPTIVE else "—")
            (outside if r.get("mesher") == OUTSIDE else srows).append((r, row))
        slug = "fem_" + ("paper" if g.startswith("paper") else "thick") + ("_strain" if "strain" in key else "_stiffness")
        title = f"Flexure FEM, {g}: {FEM_FIGURES[key]}"
        label = f"relative {FEM_FIGURES[key]} error"
        sec, p = section(title, [x for _, x in srows], out_dir, slug, error_label=label,
                         resolution=rr["ref"]["uncertainty"] / abs(R),
                         reference=f"{R:.6g} (gmsh P{rr['ref_order']} Richardson limit, ± {rr['ref']['uncertainty'] / abs(R):.2%})",
                         outside=[x for _, x in outside])
        sec[0] = "#" + sec[0]
        sec.insert(4, "The finest gmsh P2 level is the reference's own finest value (error 0 by construction): "
                      "listed, not plotted." if any(x["error"] == 0 for _, x in srows) else "")
        if outside:
            sec = sec[:-1] + ["", "Outside point of comparison (★ in the plot is not ours; not on the Pareto front):", "",
                              "| setting | DOFs | wall time | " + label + " | value | our P2 on the same mesh: DOFs, wall time (six load cases), value | relative difference |",
                              "|---|---|---|---|---|---|---|"]
            for r, x in outside:
                mine = [q for q in rows if q["geometry"] == g and q.get("mesher", "gmsh") == "gmsh"
                        and q["order"] == r["order"] and q["h_factor"] == r["h_factor"]]
                ours = (f"{mine[0]['dofs']:,}, {_fmt_t(mine[0]['time_s'])}, {mine[0][key]:.6g} | "
                        f"{abs(r[key] / mine[0][key] - 1):.1e}") if mine else "not run | —"
                sec.append(f"| {x['setting']} | {x['dofs']:,} | {_fmt_t(x['time_s'])} | {x['error']:.3g} | "
                           f"{x['value']:.6g} | {ours} |")
            sec.append("")
        lines += sec
        pngs += p
    return lines, pngs
