"""Goal-oriented adaptive analysis of a flexure design: one coarse gmsh mesh, then nested local
refinement (flexure.refine) where the dual-weighted residuals of the goals are large, until every
goal's error estimate is below ``rtol`` or a budget stops it.

Level ℓ: solve the torque case and the gauges' duals together (flexure.goals; the previous
level's fields prolongated as the CG's initial guess), read the goals J — the hub rotation θ
(stiffness k = 1/θ) and each gauge's strain (their bridge combination ε_ref too) — and their raw
DWR estimates η_ℓ ≈ J − J_ℓ (flexure.dwr). Mark the elements with the largest sum of the goals'
indicators (each goal weighted by 1/|J| while it is not yet converged), as many as the DOFs the
next level needs to just reach rtol at the goals' convergence rates (flexure.adaptive_sizing), and
bisect them (closure keeps the mesh conforming; new boundary nodes go onto the true surface).

Geometry and boundary conditions, the same problem on every level. The first mesh's boundary
vertices (an STL's: gmsh puts them off the facets) and boundary mid-edge nodes are put on the true
surface (isoparametric P2; refine.snap), new boundary nodes too at every refinement; boundary edges
whose P2 curve is still off the surface by δ > GEOMETRY_SHARE · rtol · R (R the edge's radius of
curvature) are marked as well, a geometric error the residuals do not see. On an STL that error of each
goal is also estimated, as the shape derivative of the P2 boundary moved onto the facets,
δJ ≈ Σ s_f ∫ V_n σ(u):ε(z) dΓ (flexure.geometry_error; s_f −1 on free faces, +1 on held ones), and
added, signed, to the enriched goal change (``_with_geometry``): 2 |J(u⁺) + δJ − J(u_h)|. The load and fixed
node sets are chosen once, by the radius bands on the first mesh, and handed down by prolongating
their indicators (``_nested_selections``): re-selecting by the bands on every level would move
the edge of the Dirichlet set as it is refined.

Estimate (rigid coupling). u⁺ is the Galerkin solution in the enriched space V⁺ = P2 ⊕ W on the
same mesh (W the hierarchical cubic surplus: one edge cubic per edge, one bubble per face), its
error e⁺ = u⁺ − u_h solved once per level as one system (flexure.enriched: block-preconditioned CG,
the P2 solver's p-multigrid cycle on V_h, block Jacobi on W); every goal J is linear in u (θ, each
gauge, the bridge strain), so J(u⁺) − J(u_h) = J(e⁺) for all of them from that one solve. If the
enriched goal error is at most half the P2 one (saturation, |J − J(u⁺)| ≤ q |J − J(u_h)|, q ≤ ½),

    e = ENRICHED_FACTOR · |J(u⁺) − J(u_h)| ∈ [2(1 − q), 2(1 + q)] · |J − J(u_h)| ⊂ [1, 3] · |J − J(u_h)|

whatever the signs: no calibration, hence MIN_LEVELS = 1. Measured q (benchmarks/fem_annulus.py,
exact torsion field on exact circles): 0.01–0.12 on every goal at 5–60 k dofs, except where the
P2 error itself is ~0.003 % (a sign change). Next to re-entrant edges V⁺ only about halves the error
(q 0.3–0.6): from the second level on, q̂ = (J⁺_ℓ − J⁺_(ℓ−1))/(J_ℓ − J_(ℓ−1)) of each goal is measured
between the nested levels (same q on both) and e = max(2, 1.5/(1 − q̂)) |J(u⁺) − J(u_h)|; where q̂ is not
measured (the first level), on a part with a sharp re-entrant edge (flexure.reentrant) q = 4/9 of its
singular exponent ½, e = 2.7 |J(u⁺) − J(u_h)|, on others the flat 2 |J(u⁺) − J(u_h)|
(flexure.saturation: the derivations, and where q̂ is not a measurement). The bridge strain is its own
linear goal, its estimate f_ref |d_ref| + Σ |s_i d_i| |f_i − f_ref| / 4 (f the factors max(2, 1.5/(1 − q̂)) of
the bridge and of each arm, saturation.bridge_estimate): a single q̂ of the bridge's d undercounts where
the arms saturate differently and their errors partly cancel. Each arm's estimate is at least the gauge
set's q times the median of the arms' (saturation.arm_floor: saturation holds for the gauge set, not for an
arm whose own error is small next to the others').
On an STL, d = J(u⁺) − J(u_h) includes the geometric error δJ above; a CAD/STEP part's P2 boundary is
isoparametric on the exact surface and gets no geometric term.
The distributed coupling (its traction on W not assembled yet) keeps the calibrated DWR estimate:
the raw DWR sum η_ℓ (Bank–Weiser primal weight, flexure.bank_weiser) divided by its effectivity
measured over the last refinement step,

    κ̂_ℓ = (η_(ℓ−1) − η_ℓ) / (J_ℓ − J_(ℓ−1)),        e_ℓ = SAFETY · |η_ℓ| / clip(κ̂_ℓ, KAPPA_MIN, 1)

(κ̂ a measurement only where the estimate fell by at least MIN_DROP of itself and kept its sign;
else the previous κ̂, or 1), the bridge strain through its arms, Σ |s_i| e_i / 4. The marking uses
the DWR vertex indicators either way.

Stop. Every goal's estimate relative to its scale is below ``rtol``: the stiffness's its value, a
strain's its magnitude but not below the arms' mean magnitude (``_strain_scales``: a gauge where the
strain nearly vanishes, or a bridge whose arms nearly cancel, has no 1 % of itself to reach).
"""

from __future__ import annotations

import math
import sys
import time

import numpy as np

from userio.errors import InputError
from flexure import adaptive_sizing as sizing
from flexure import blas, rss
from flexure import reentrant, saturation

DEFAULT_RTOL = 0.02
#: the first mesh: the design's size function × this, its curved faces resolved as at
#: CURVATURE_SHARE × this (h × 1: 12 elements per turn): the refinement cannot bring back the true
#: shape of a hole meshed as a polygon of few sides (its nodes would have to move by a large part of
#: the elements next to them), so curved faces are resolved from the start
INITIAL_H_FACTOR = 2.0
CURVATURE_SHARE = 0.5
#: bisection rounds per level (1: each marked element halved once, + closure); how many elements
#: are marked: flexure.adaptive_sizing (a step sized to just reach rtol)
ROUNDS = 2
SAFETY = 1.5
#: the geometry criterion's share of --rtol (δ/R of a boundary edge, ``_geometry_marks``)
GEOMETRY_SHARE = 0.1
KAPPA_MIN = 0.25
MIN_DROP = 0.25
MIN_LEVELS = 1
#: the enriched estimate's first-level factor: 2 |J(u⁺) − J(u_h)| brackets within [1, 3] when
#: |J − J(u⁺)| ≤ ½ |J − J(u_h)|; later levels: flexure.saturation
ENRICHED_FACTOR = saturation.FLAT
MAX_LEVELS = 14
MAX_DOFS = 2_000_000
MAX_MEMORY_GB = 3.0
#: the bridge's arm signs (bridge.wheatstone "full_bending": ε1 − ε2 + ε3 − ε4)
ARM_SIGN = {1: 1.0, 2: -1.0, 3: 1.0, 4: -1.0}
METHOD = ("goal-oriented (dual-weighted residual) estimate on nested adaptively refined meshes "
          "({levels}, {dofs} dofs): the raw DWR estimate {raw} divided by its effectivity measured "
          "over the last refinement step ({kappa}) and × {safety}; a bound-like figure, not 1σ")

METHOD_ENRICHED = ("goal-oriented estimate on nested adaptively refined meshes ({levels}, {dofs} dofs): "
                   "max({factor:g}, 1.5/(1 − q̂)) × |J(u⁺) − J(u_h)|, u⁺ the solution in the enriched space P2 ⊕ "
                   "cubic surplus on the last mesh (one global solve, flexure.enriched), q̂ the ratio of the enriched "
                   "to the P2 error measured between the last two nested levels (flexure.saturation; where it is not "
                   "measured, as on one level, q̂ = 4/9 on a part with a sharp re-entrant edge: 2.7×); brackets the error within "
                   "[1, 3]× where q̂ is the ratio on the last level within [⅔, 2] of (1 − q) (unmeasured: "
                   "q ∈ [−0.11, 0.63]); the bridge's plus what its arms' different q̂ may add; each arm's at least the gauge set's q × the arms' median; a bound-like "
                   "figure, not 1σ; on an STL, J(u⁺) includes the P2 boundary's geometric error against the facets "
                   "(flexure.geometry_error)")


def geometry(design, mres):
    """(TaggedMesh, projector or None) of an initial mesh: gmsh's classification on an exact CAD
    solid (spoke disc, STEP: projection with gmsh), the STL's triangles (trimesh), or none (the
    polygonal sweep/tetgen meshes, whose faces are flat)."""
    from flexure.project import CadProjector, StlProjector, classify, stl_tagged
    from flexure.refine import TaggedMesh

    mesh = mres.mesh
    ent = mesh._cache.get("entities")
    if design.kind == "stl":
        projector = StlProjector(mres.surface)
        return stl_tagged(mesh, projector), projector
    if ent is not None and design.mesher == "gmsh":
        if design.kind == "spoke_disc":
            from flexure.gmsh_mesh import build_spoke_disc
            disc = design.disc
            return classify(mesh, *ent), CadProjector(lambda g: build_spoke_disc(g, disc))
        if design.kind == "step":
            from flexure.cad import import_step
            path = design.file_path
            return classify(mesh, *ent), CadProjector(lambda g: import_step(g, path))
    return TaggedMesh.untagged(mesh), None


def start_mesh(design, size: str | None = None, initial_h_factor: float = INITIAL_H_FACTOR,
               max_elements: float | None = None):
    """The first mesh (meshing.MeshResult): the design's size field × ``initial_h_factor``, curved
    faces resolved as at CURVATURE_SHARE × it, an STL's too (stl_remesh.mesh_surface ``curvature``:
    its nodes can then all be put on the STL, refine.snap); made again finer only for a tetrahedron
    below gmsh_mesh.ADAPTIVE_START_DEG."""
    from flexure import gmsh_mesh
    from flexure.analysis import build_mesh

    with gmsh_mesh.finer_below(gmsh_mesh.ADAPTIVE_START_DEG):
        return build_mesh(design, size, 2, initial_h_factor, max_elements,
                          curvature_h_factor=CURVATURE_SHARE * initial_h_factor, stl_curvature=True)


def goal_values(design, sol) -> dict:
    """Figures of one level: θ, k = 1/θ, each gauge's strain, the bridge strain ε_ref."""
    arms = [g.arm for g in design.gauges]
    s = np.array([ARM_SIGN.get(a, 0.0) for a in arms])
    return {"theta": sol.theta, "eps": sol.eps.copy(), "eps_ref": float(s @ sol.eps / 4.0), "sign": s}


def calibrate(eta_prev: float, eta: float, J_prev: float, J: float, kappa_prev: float | None) -> tuple[float, str]:
    """κ̂ = (η_(ℓ−1) − η_ℓ)/(J_ℓ − J_(ℓ−1)) clipped to [KAPPA_MIN, 1] where it is a measurement
    (module docstring), else the previous κ̂, or 1 → (κ used, how)."""
    dJ = J - J_prev
    drop = abs(eta_prev) - abs(eta)
    if dJ != 0 and drop >= MIN_DROP * abs(eta_prev) and eta_prev * eta > 0:
        k = (eta_prev - eta) / dJ
        if math.isfinite(k) and k > 0:
            return float(min(max(k, KAPPA_MIN), 1.0)), "measured"
    if kappa_prev is not None:
        return kappa_prev, "previous level's"
    return 1.0, "not measured yet"


@blas.single_threaded
def analyze_adaptive(design, size: str | None = None, rtol: float | None = None, max_dofs: int = MAX_DOFS,
                     max_memory_gb: float = MAX_MEMORY_GB, progress: bool = False,
                     max_elements: float | None = None, initial_h_factor: float = INITIAL_H_FACTOR,
                     max_seconds: float | None = None):
    """Adaptive analysis (module docstring) → (results as ``analysis.analyze`` gives them on the
    final mesh, with ``<figure>_error_estimate``/``_error_method``, the levels and what stopped
    the refinement; Fields). ``initial_h_factor``: the first mesh's coarsening of the size field;
    ``max_seconds``: a wall-time budget for the analysis from its meshing on (flexure.adaptive_sizing,
    "Time": the next level within what is left of it; the first level is always solved)."""
    from flexure import goal_cases
    from flexure.analysis import _selections, analyze_mesh
    from flexure.enriched import goal_errors
    from flexure.goals import ALGEBRAIC_SHARE, cg_rtol_for, solve_goals
    from flexure.meshing import MeshResult, mesh_report
    from flexure.mesh import quality
    from flexure.node_order import renumbered
    from flexure.refine import bisect, snap

    rtol = DEFAULT_RTOL if rtol is None else rtol
    if not (math.isfinite(rtol) and 0 < rtol < 1):
        raise InputError(f"--rtol: must be in (0, 1), got {rtol!r}")
    if (design.order or 2) != 2:
        raise InputError("adaptive refinement needs order 2 (10-node tetrahedra); use the levels estimate for P1")
    if max_seconds is not None and not (math.isfinite(max_seconds) and max_seconds > 0):
        raise InputError(f"--max-seconds: must be a positive number of seconds, got {max_seconds!r}")
    t_start = time.perf_counter()
    t0 = time.perf_counter()
    bar = _bar(progress)
    hist, kappas = [], {}
    prev_rel = predicted_gb = None
    mem_per = 0.0
    gain, split_done = None, False       # DOFs per mark of the last refinement (marks_for); next_dofs's split
    x0 = ref0 = projector = None
    stopped = None
    try:
        bar.set_description("flexure: meshing")
        mres = start_mesh(design, size, initial_h_factor, max_elements)
        tm, projector = geometry(design, mres)
        snapped = snap(tm, projector, getattr(projector, "snap_vertices", False)) if projector is not None else {}
        tm = renumbered(tm)[0]                 # nodes in space-filling-curve order (flexure.node_order)
        bands = _band_indicator(tm.mesh, _selections(design, tm.mesh))
        q_unmeasured = saturation.unmeasured_ratio(reentrant.has_sharp_reentrant_edge(tm.mesh))   # flexure.saturation (4)
        mesh_s = time.perf_counter() - t0
        base_gb = rss.now_gb(trim=True)
        bar.set_description(f"flexure: mesh {tm.mesh.n_dofs} dofs ({mesh_s:.0f} s)")
        for lv in range(MAX_LEVELS):
            mesh = tm.mesh
            tl = time.perf_counter()
            peak_before = rss.peak_gb()
            # CG tied to --rtol; the goals dual-corrected and their algebraic error held below a share of it
            sol = solve_goals(design, mesh, x0, ref0, selections=_nested_selections(mesh, bands),
                              rtol=cg_rtol_for(rtol), algebraic_limit=ALGEBRAIC_SHARE * rtol)
            x0 = None                          # the CG's start, used: free it before the enriched solve
            te = time.perf_counter()
            enr = goal_errors(design, mesh, sol, release=True)   # J(u⁺) − J(u_h), V⁺ = P2 ⊕ cubic surplus
            if enr is not None and "goal_dual_correction" in sol.info:   # against the reported, corrected goals
                d = np.asarray(sol.info["goal_dual_correction"])
                enr["theta"], enr["gauges"] = enr["theta"] - float(d[0]), enr["gauges"] - d[1:]
            enriched_s = time.perf_counter() - te
            rss_level = rss.now_gb()          # the level's fields alive (its peak: the P2 or the enriched solve's)
            sol.solver = sol.system = None     # not needed again (the last mesh's load cases: goal_cases): free them
                                               # (released already by goal_errors where it could)
            vals = goal_values(design, sol)
            weight = None if enr is None else enr.pop("weight")
            rec = {"level": lv, "dofs": int(mesh.n_dofs), "elements": int(mesh.n_elements),
                   "theta": vals["theta"], "torsional_stiffness_Nm_per_rad": 1.0 / vals["theta"],
                   "gauge_strain_per_Nm": vals["eps_ref"], "gauge_strains": vals["eps"].tolist(),
                   "q_unmeasured": q_unmeasured,
                   "eta": None, "dwr_s": None,   # the DWR indicators: _dwr_indicators, only where they are used
                   "safety_factor": None,      # below: only where the run goes on (the last level's: the final figures')
                   "cg_iterations": sol.info.get("iterations"), "solve_s": sol.info["total_s"],
                   "goal_algebraic_error": sol.info.get("goal_algebraic_error"),
                   "enriched": None if enr is None else {
                       "theta": enr["theta"], "gauges": enr["gauges"].tolist(),
                       "eps_ref": float(vals["sign"] @ enr["gauges"] / 4.0), **enr["info"]},
                   "enriched_s": enriched_s,
                   "min_dihedral_deg": float(quality(mesh)["min_dihedral_deg"]), "pending_nodes": int(len(tm.pending[0]))}
            # the calibrated estimate needs the indicators' sums now; the enriched one never (the marking does)
            eta_v = _dwr_indicators(rec, design, mesh, sol, weight, vals["sign"]) if enr is None else None
            tg = time.perf_counter()
            geo_marked, rec["geometry"] = _geometry_marks(tm, projector, rtol, design, sol)
            rec["geometry"]["s"] = time.perf_counter() - tg
            rec.update(_estimates(rec, hist[-1] if hist else None, kappas, design))
            hist.append(rec)
            rel = _relative(rec)
            worst = _worst(rel)
            bar.update(1)
            bar.set_description(f"flexure: level {lv} {mesh.n_dofs} dofs, worst error ±{worst:.2%}"
                                + (f", {time.perf_counter() - t_start:.0f} s of {max_seconds:g} s" if max_seconds else ""))
            rec["level_s"] = time.perf_counter() - tl
            rec["peak_rss_gb"] = rss.peak_gb()
            rec["predicted_peak_gb"] = predicted_gb        # by the level before (None on the first)
            # this level's peak: the process's if the level raised it, else the largest sampled RSS
            level_peak = max(rss_level, rss.now_gb(), rec["peak_rss_gb"] if rec["peak_rss_gb"] > peak_before else 0.0)
            if enr is not None and not rec["enriched"].get("converged", True):   # no estimate to mark or stop by
                stopped = "unconverged"
                break
            if worst <= rtol and lv + 1 >= MIN_LEVELS:
                stopped = "rtol"
                break
            if lv + 1 == MAX_LEVELS:
                stopped = "max_levels"
                break
            # the next level: sized to just reach rtol, within the budgets (flexure.adaptive_sizing)
            goals_rel = {"dofs": rec["dofs"], "rel": [rel["torsional_stiffness_Nm_per_rad"], *rel["arms"]],
                         "raw": sizing.raw_relative(rec, rel, _with_geometry(rec) if rec.get("enriched") else None)}
            grow = sizing.min_growth(MIN_DROP)
            rise = sizing.FACTOR_RISE if rec.get("enriched") and prev_rel is None else 1.0
            step = (mesh.n_dofs, goals_rel["rel"], sizing.rates(prev_rel, goals_rel), rtol, grow, rise)
            want, hope = sizing.target_dofs(*step), sizing.hopeful_target(*step)
            mem_per = sizing.peak_per_dof(mesh.n_dofs, base_gb, level_peak, mem_per, rec["peak_rss_gb"] > peak_before)
            mem_cap = sizing.memory_dofs(base_gb, mem_per, max_memory_gb)
            # the refinement that made this level, or on the first one the prior (flexure.adaptive_sizing, "Time")
            into = (hist[-2].get("refine_s") or 0.0) if lv else sizing.REFINE_S_PER_DOF * rec["dofs"]
            per_s = sizing.seconds_per_dof(rec["dofs"], rec["level_s"] + into)
            time_cap = math.inf if max_seconds is None else \
                sizing.time_dofs(max_seconds - (time.perf_counter() - t_start), per_s)
            caps = {"max_dofs": max_dofs, "memory": mem_cap, "time": time_cap}
            cap = min(caps.values())
            nxt = sizing.next_dofs(mesh.n_dofs, want, cap, grow, split=not split_done, prior=prev_rel is None,
                                   spent=time_cap, hope=hope)
            split_done = split_done or cap < want or 0 < nxt < min(want, cap)     # one split per run
            rec["sizing"] = {"target_dofs": int(want), "hopeful_target_dofs": int(hope), "memory_cap_dofs": int(mem_cap),
                            "base_rss_gb": base_gb, "level_peak_gb": level_peak, "peak_per_dof_gb": mem_per,
                            "next_dofs": int(nxt), "factor_rise": rise, "seconds_per_dof": per_s,
                            "time_cap_dofs": None if max_seconds is None else int(time_cap)}
            prev_rel = goals_rel
            if nxt == 0:                                       # a budget leaves no measurable step: the smallest
                stopped = min(caps, key=caps.get)             # (the first of equal ones)
                break
            if eta_v is None:                 # a level the run goes on from: its indicators mark the next
                eta_v = _dwr_indicators(rec, design, mesh, sol, weight, vals["sign"])
                rec["level_s"] += rec["dwr_s"]
            weight = None
            weights = np.array([1.0 / max(abs(rec["theta"]), 1e-300)]
                               + [1.0 / s for s in _strain_scales(rec["gauge_strains"])])
            open_goals = np.array([rel["torsional_stiffness_Nm_per_rad"] > rtol]
                                  + [r > rtol for r in rel["arms"]])
            w = weights * np.where(open_goals, 1.0, 1e-3)
            tr = time.perf_counter()
            from flexure.dwr import element_indicators
            marked, rec["sizing"]["marks"] = sizing.marks_for(tm, element_indicators(mesh, eta_v) @ w, nxt, ROUNDS,
                                                              geo_marked, gain=gain, limit=cap)
            gain = rec["sizing"]["marks"]["gain"] or gain
            rec["safety_factor"] = _safety_factor(design, mesh, sol.U[:, :, 0])
            ref0 = sol.q[-6:].copy() if design.coupling == "rigid" else None    # not a view keeping all of q
            new, (x0, bands_new), rinfo = bisect(tm, marked, [sol.U, bands], rounds=ROUNDS, projector=projector)
            new, (x0, bands_new), _ = renumbered(new, (x0, bands_new))
            if rinfo.get("invalid_elements"):       # folded on the true surface past mending: this level is the answer
                rec["invalid_elements"], stopped = int(rinfo["invalid_elements"]), "invalid_mesh"
                break
            tm, bands = new, bands_new
            sol = None                                       # free the old level's matrix and hierarchy
            rss.now_gb(trim=True)                           # ... and give the freed heap back to the system
            rec["refine_s"] = time.perf_counter() - tr
            predicted_gb = sizing.predicted_peak_gb(tm.mesh.n_dofs, base_gb, mem_per)
            rec["marked"] = int(len(marked))
            rec["projection"] = {k: rinfo.get(k, 0) for k in ("projected", "projection_partial", "projection_undone")}
    finally:
        bar.close()
        if hasattr(projector, "close"):
            projector.close()          # the CAD projector's gmsh session
    # the final mesh: all six load cases, the figures as analysis.analyze gives them
    mesh = tm.mesh
    report = mesh_report(mesh, mres.report["size"], "gmsh+bisection", None, _field(mres), mres.surface)
    report.update({k: mres.report[k] for k in ("h_far_m", "h_gauge_m") if k in mres.report})
    fin = MeshResult(mesh, mres.surface, report)
    res, fields = analyze_mesh(design, fin, mesh_s, progress=False, cases=goal_cases.from_goals(sol),
                               selections=_nested_selections(mesh, bands))
    hist[-1]["safety_factor"] = float(design.material.yield_Pa / res["max_von_mises_Pa"])   # the same u, mesh
    _attach(res, hist, design, rtol, stopped, max_dofs, max_memory_gb, max_seconds)
    res["mesh"]["initial_snap"] = snapped
    res["total_s"] = float(time.perf_counter() - t_start)
    return res, fields


def _dwr_indicators(rec: dict, design, mesh, sol, weight, sign) -> np.ndarray:
    """The goals' DWR vertex indicators (n, 1 + g) (flexure.goals.indicators, ``weight`` the enriched
    solve's primal weight or None); their sums into ``rec["eta"]`` (θ, each gauge, the bridge's
    Σ s_i η_i / 4) and their time into ``rec["dwr_s"]``."""
    from flexure.goals import indicators

    t0 = time.perf_counter()
    eta_v = indicators(design, mesh, sol, weight)
    eta = eta_v.sum(axis=0)
    rec["eta"] = {"theta": float(eta[0]), "gauges": eta[1:].tolist(), "eps_ref": float(sign @ eta[1:] / 4.0)}
    rec["dwr_s"] = time.perf_counter() - t0
    return eta_v


def _band_indicator(mesh, selections) -> np.ndarray:
    """(n, 2) indicators (1 on the node set, 0 off it) of the first mesh's load and fixed sets."""
    ind = np.zeros((mesh.n_nodes, 2))
    for col, nodes in enumerate(selections):
        ind[nodes, col] = 1.0
    return ind


def _nested_selections(mesh, ind: np.ndarray):
    """(load, fixed) of a refined mesh: the boundary nodes where the first mesh's set indicators,
    prolongated by the parents' P2 shape functions (refine.bisect), are 1. A node on an edge or a
    face whose P2 nodes all carry the set gets exactly 1 (the P2 trace of a constant); any other
    node less or more: so the sets cover the same part of the boundary on every level, where
    re-selecting by the radius bands would grow them as the band's edge is refined (a Dirichlet
    set, hence a problem, that changes with the mesh)."""
    bnd = np.zeros(mesh.n_nodes, bool)
    bnd[mesh.boundary_nodes()] = True
    on = (np.abs(ind - 1.0) < 1e-9) & bnd[:, None]
    return np.flatnonzero(on[:, 0]), np.flatnonzero(on[:, 1])


def _geometry_marks(tm, projector, rtol: float, design=None, sol=None):
    """The geometry criterion: elements with a boundary edge whose isoparametric P2 curve is off the
    true surface by δ > GEOMETRY_SHARE · rtol · R (R its radius of curvature from the sagitta:
    refinement.boundary_geometry_error); a boundary moved by δ over a feature of size R changes
    the goals by about δ/R, an error the residuals cannot see.

    On an STL (``design`` and the level's GoalSolution ``sol`` given) the goals' geometric error is
    measured instead of bounded by δ/R: the shape derivative δJ of the discrete boundary moved onto
    the facets (flexure.geometry_error; summary ``error``: δθ, δε per gauge, the bridge's, the
    boundary's offsets), which the estimate adds (``_with_geometry``); where a goal's |δJ| exceeds
    GEOMETRY_SHARE · rtol of its scale, the boundary elements carrying the larger half of the weighted
    Σ|δJ_face| are marked. The edges' δ/R is only recorded there: every fold between facets looks like
    curvature to it, and marking by it spent the DOFs where the goals do not feel the boundary
    (thick_disc_stl at 2 %: 99k → 311k → 436k → 682k DOFs in 251 s, three quarters of each step forced
    by it, against 99k → 296k → 384k in 118 s by δJ alone, whose |δθ|/θ stayed below 2e-4; the
    stiffness 0.38 % off its reference against 0.56 %). → (elements, summary)"""
    from flexure.refine import boundary_geometry_error

    if projector is None:
        return np.zeros(0, np.int64), {"max_rel": 0.0, "max_m": 0.0, "marked": 0}
    e, dist, R = boundary_geometry_error(tm, projector)
    rel = dist / np.maximum(R, 1e-300)
    summary = {"max_rel": float(rel.max(initial=0.0)), "max_m": float(dist.max(initial=0.0))}
    if sol is None or design is None or design.kind != "stl":
        bad = np.unique(e[rel > GEOMETRY_SHARE * rtol])
        return bad, {**summary, "marked": len(bad)}
    from flexure.geometry_error import goal_geometry_errors

    sign = np.array([ARM_SIGN.get(g.arm, 0.0) for g in design.gauges])
    err, elems, terms = goal_geometry_errors(tm.mesh, projector, design.material, sol.U, sol.constrained, sign)
    w = np.r_[1.0 / max(abs(sol.theta), 1e-300), 1.0 / _strain_scales(sol.eps)]
    rel_goal = np.abs(np.r_[err["theta"], err["gauges"]]) * w
    bad = np.zeros(0, np.int64)
    if rel_goal.max(initial=0.0) > GEOMETRY_SHARE * rtol:
        score = np.abs(terms) @ w
        order = np.argsort(score)[::-1]
        n = int(np.searchsorted(np.cumsum(score[order]), 0.5 * score.sum())) + 1
        bad = np.unique(elems[order[:n]])
    err["marked"] = int(len(bad))
    return bad, {**summary, "marked": int(len(bad)), "error": err}


def _with_geometry(rec: dict) -> dict:
    """The enriched goal changes J(u⁺) − J(u_h) plus the goals' geometric error δJ where it was estimated
    (``_geometry_marks``), signed: J(u⁺) + δJ approximates the goal on the true part, so the estimate
    2 |J(u⁺) + δJ − J(u_h)| brackets as the enriched one does wherever |J − J(u⁺) − δJ| ≤ ½ |J − J(u_h)|."""
    d = rec["enriched"]
    g = (rec.get("geometry") or {}).get("error")
    if not g:
        return d
    return {**d, "theta": d["theta"] + g["theta"], "gauges": (np.asarray(d["gauges"]) + g["gauges"]).tolist(),
            "eps_ref": d["eps_ref"] + g["eps_ref"]}


def _safety_factor(design, mesh, u_unit) -> float:
    """σ_y / max von Mises at the rated torque (element-nodal stresses, as analysis.analyze)."""
    from flexure.post import element_nodal_strains, stress_measures

    vm = stress_measures(element_nodal_strains(mesh, u_unit * design.rated_torque_Nm), design.material)[0]
    return float(design.material.yield_Pa / vm.max())


def _field(mres):
    from flexure.meshing import SizeField

    r = mres.report
    return SizeField(r.get("h_far_m", math.nan), r.get("h_gauge_m", math.nan), np.zeros((0, 3)), 0.0)


def _bar(progress: bool):
    from tqdm import tqdm

    return tqdm(total=None, file=sys.stderr, disable=not progress, unit="level", leave=False)


def _estimates(rec: dict, prev: dict | None, kappas: dict, design) -> dict:
    """Calibrated error estimates of this level's goals (module docstring), absolute, in the
    goals' units: θ (then k), each gauge, ε_ref."""
    if rec.get("enriched"):
        return _enriched_estimates(rec, prev, kappas, [ARM_SIGN.get(g.arm, 0.0) for g in design.gauges])
    eta = rec["eta"]
    J = {"theta": rec["theta"], "eps_ref": rec["gauge_strain_per_Nm"],
         **{f"g{i}": e for i, e in enumerate(rec["gauge_strains"])}}
    E = {"theta": eta["theta"], "eps_ref": eta["eps_ref"], **{f"g{i}": e for i, e in enumerate(eta["gauges"])}}
    out, how = {}, {}
    for key in J:
        if prev is None:
            k, h = 1.0, "no previous level"
        else:
            Jp = {"theta": prev["theta"], "eps_ref": prev["gauge_strain_per_Nm"],
                  **{f"g{i}": e for i, e in enumerate(prev["gauge_strains"])}}[key]
            Ep = {"theta": prev["eta"]["theta"], "eps_ref": prev["eta"]["eps_ref"],
                  **{f"g{i}": e for i, e in enumerate(prev["eta"]["gauges"])}}[key]
            k, h = calibrate(Ep, E[key], Jp, J[key], kappas.get(key))
        kappas[key] = k
        out[key] = SAFETY * abs(E[key]) / k
        how[key] = (k, h)
    # the bridge strain ε_ref = Σ s_i ε_i / 4 is bounded through its arms, |E_ref| ≤ Σ |s_i| |E_i| / 4:
    # its own DWR sum lets the arms' estimates cancel where their errors need not (module docstring)
    s = np.abs(np.asarray([ARM_SIGN.get(g.arm, 0.0) for g in design.gauges]))
    out["eps_ref"] = float(s @ np.array([out[f"g{i}"] for i in range(len(s))]) / 4.0)
    how["eps_ref"] = (how["eps_ref"][0], "its arms' estimates, Σ|s_i| e_i / 4")
    k_est = out["theta"] / abs(rec["theta"]) * rec["torsional_stiffness_Nm_per_rad"]
    return {"estimate": {"torsional_stiffness_Nm_per_rad": k_est, "gauge_strain_per_Nm": out["eps_ref"],
                         "gauge_strains": [out[f"g{i}"] for i in range(len(rec["gauge_strains"]))]},
            "kappa": {k: v[0] for k, v in how.items()}, "kappa_how": {k: v[1] for k, v in how.items()}}


def _enriched_estimates(rec: dict, prev: dict | None = None, q_seen: dict | None = None,
                        signs=None) -> dict:
    """Every goal's estimate from its enriched difference d = J(u⁺) − J(u_h) (flexure.saturation):
    max(2, 1.5/(1 − q̂))|d|, q̂ measured between this nested level and ``prev``, else the goal's last
    measured one, else a re-entrant edge's; absolute, in the goals' units: θ (then k), each gauge, the
    bridge strain (its own linear goal, + what its arms' different q̂ may add: saturation.bridge_estimate).
    ``q_seen`` {goal: last measured q̂}, updated; ``signs`` the bridge's arm signs s_i."""
    from flexure.saturation import arm_floor, bridge_estimate, goal_estimate

    q_seen = {} if q_seen is None else q_seen
    vals, diffs = _goal_table(rec)
    pv, pd = _goal_table(prev) if prev and prev.get("enriched") else (None, None)
    noise = _algebraic_noise(rec, vals) + (_algebraic_noise(prev, pv) if pv is not None else 0.0)
    est, q, how = {}, {}, {}
    for i, key in enumerate(_goal_keys(len(vals))):
        g = goal_estimate(vals[i], diffs[i], None if pv is None else (pv[i], pd[i]), noise[i],
                          q_seen.get(key, math.nan), rec.get("q_unmeasured"))
        est[key], q[key], how[key] = g.e, g.q, g.how
        if g.measured:
            q_seen[key] = g.q
    arms = [est[f"g{i}"] for i in range(len(vals) - 2)]
    floored = arm_floor(arms, [q[f"g{i}"] for i in range(len(arms))], rec.get("q_unmeasured"))
    for i in np.flatnonzero(floored > np.asarray(arms)):
        how[f"g{i}"] += "; held at the gauge set's floor, its q × the arms' median (saturation.arm_floor)"
    arms = floored.tolist()
    if signs is not None:
        comb = bridge_estimate(np.asarray(signs, float), diffs[2:], np.array(arms), diffs[1], est["eps_ref"])
        if comb > est["eps_ref"]:
            est["eps_ref"], how["eps_ref"] = comb, how["eps_ref"] + "; + its arms' saturation differences"
    k_est = est["theta"] / abs(rec["theta"]) * rec["torsional_stiffness_Nm_per_rad"]
    return {"estimate": {"torsional_stiffness_Nm_per_rad": k_est, "gauge_strain_per_Nm": est["eps_ref"],
                         "gauge_strains": arms},
            "kappa": q, "kappa_how": how}


def _count(n: int, noun: str) -> str:
    return f"{n} {noun}" + ("" if n == 1 else "s")


def _goal_keys(n: int) -> list[str]:
    return ["theta", "eps_ref"] + [f"g{i}" for i in range(n - 2)]


def _goal_table(rec: dict) -> tuple[np.ndarray, np.ndarray]:
    """(J, d) of a level's goals in the order of ``_goal_keys``: θ, the bridge strain, each gauge; d the
    enriched change plus the STL's geometric error where estimated (``_with_geometry``)."""
    d = _with_geometry(rec)
    J = np.array([rec["theta"], rec["gauge_strain_per_Nm"], *rec["gauge_strains"]], float)
    return J, np.array([d["theta"], d["eps_ref"], *d["gauges"]], float)


def _algebraic_noise(rec: dict, J: np.ndarray) -> np.ndarray:
    """Absolute algebraic error of each goal of a level: its solve's relative goal error (flexure.goals,
    against |θ| and the strains' scales) × the scale, and round-off."""
    rel = rec.get("goal_algebraic_error")
    rel = 1e-8 if rel is None or not math.isfinite(rel) else float(rel)
    scale = np.abs(J)
    scale[1:] = np.maximum(scale[1:], np.abs(J[2:]).mean() if len(J) > 2 else 0.0)
    return (rel + 1e-12) * scale


def _strain_scales(eps) -> np.ndarray:
    """The scale each gauge strain's error is measured against: |ε_i|, but not below the arms' mean
    magnitude ε̄ = Σ|ε_j|/n. A gauge placed where the strain nearly vanishes (or a bridge whose arms
    nearly cancel) has no 1 % of itself to reach: relative to itself its error estimate never
    converges (the thin annulus of benchmarks/fem_annulus.py, arms at 30–65° off radial: the bridge
    strain's relative estimate kept --rtol 0.01 refining to the memory budget with every arm's
    estimate at 0.05 %), and it is the bridge's magnitude scale that the reading is judged on."""
    a = np.abs(np.asarray(eps, float))
    return np.maximum(a, max(float(a.mean()) if len(a) else 0.0, 1e-300))


def _relative(rec: dict) -> dict:
    """Relative error estimates of one level: stiffness, bridge strain, each arm (list); the strains
    against ``_strain_scales``."""
    e = rec["estimate"]
    scale = _strain_scales(rec["gauge_strains"])
    arms = [x / s for x, s in zip(e["gauge_strains"], scale)]
    bar = max(abs(rec["gauge_strain_per_Nm"]), float(np.mean(np.abs(rec["gauge_strains"]))), 1e-300)
    return {"torsional_stiffness_Nm_per_rad": e["torsional_stiffness_Nm_per_rad"] / abs(rec["torsional_stiffness_Nm_per_rad"]),
            "gauge_strain_per_Nm": e["gauge_strain_per_Nm"] / bar,
            "arms": arms}


def _worst(rel: dict) -> float:
    return max([rel["torsional_stiffness_Nm_per_rad"], rel["gauge_strain_per_Nm"], *rel["arms"]])


def _attach(res: dict, hist: list, design, rtol: float, stopped: str, max_dofs: int, max_memory_gb: float,
            max_seconds: float | None = None) -> None:
    """Error keys beside the figures of ``res`` (the final level), the levels, the stop."""
    last = hist[-1]
    est = last["estimate"]
    kap = last["kappa"]
    n = len(hist)

    def method(key_eta: str, key_kappa: str, J: float) -> str:
        if last.get("enriched"):
            return METHOD_ENRICHED.format(levels=_count(n, 'level'), dofs=last["dofs"], factor=ENRICHED_FACTOR)
        raw = abs(last["eta"][key_eta] if key_eta != "gauges" else 0.0) / max(abs(J), 1e-300)
        return METHOD.format(levels=_count(n, 'level'), dofs=last["dofs"], raw=f"{raw:.2%}",
                             kappa=f"κ = {kap[key_kappa]:.2f}, {last['kappa_how'][key_kappa]}", safety=SAFETY)

    e_k = est["torsional_stiffness_Nm_per_rad"]
    e_s = est["gauge_strain_per_Nm"]
    rel_s = e_s / max(abs(last["gauge_strain_per_Nm"]), 1e-300)
    res["torsional_stiffness_Nm_per_rad_error_estimate"] = float(e_k / last["torsional_stiffness_Nm_per_rad"]
                                                                 * res["torsional_stiffness_Nm_per_rad"])
    res["torsional_stiffness_Nm_per_rad_error_method"] = method("theta", "theta", last["theta"])
    res["gauge_strain_per_Nm_error_estimate"] = float(rel_s * abs(res["gauge_strain_per_Nm"]))
    res["gauge_strain_per_Nm_error_method"] = method("eps_ref", "eps_ref", last["gauge_strain_per_Nm"]) if \
        last.get("enriched") else (
        "its arms' adaptive estimates combined by the triangle inequality, Σ|s_i| e_i / 4 (s_i the bridge's arm "
        f"signs; each arm: {METHOD.format(levels=_count(n, 'level'), dofs=last['dofs'], raw='η', kappa='κ per arm', safety=SAFETY)})")
    res["sensitivity_mV_per_V_per_Nm_error_estimate"] = float(rel_s * abs(res["sensitivity_mV_per_V_per_Nm"]))
    res["sensitivity_mV_per_V_per_Nm_error_method"] = ("the bridge strain's relative estimate (the sensitivity "
                                                       "is proportional to it)")
    arms = [g.arm for g in design.gauges]
    res["gauge_strains_per_Nm_error_estimate"] = {
        f"arm{a}": float(e) for a, e in zip(arms, est["gauge_strains"])}
    if len(hist) >= 2:
        res["safety_factor_error_estimate"] = float(abs(hist[-1]["safety_factor"] - hist[-2]["safety_factor"]))
        res["safety_factor_error_method"] = (
            "its change over the last refinement step; not a bound: the peak stress is not a goal of the "
            "refinement, and at a sharp edge it need not converge")
    else:
        res["safety_factor_error_estimate"] = math.nan
        res["safety_factor_error_method"] = "not estimated (one level)"
    if stopped == "unconverged":
        for k in ("torsional_stiffness_Nm_per_rad", "gauge_strain_per_Nm", "sensitivity_mV_per_V_per_Nm",
                  "safety_factor"):
            res[f"{k}_error_estimate"] = math.nan
            res[f"{k}_error_method"] = "withheld: the enriched solve of the estimate did not converge"
        res["gauge_strains_per_Nm_error_estimate"] = {k: math.nan for k in res["gauge_strains_per_Nm_error_estimate"]}
    res["discretization_levels"] = hist
    res["error_method"] = "adaptive"
    res["rtol"] = rtol
    res["max_seconds"] = max_seconds
    res["stopped_by"] = stopped
    worst = _worst(_relative(last))
    if stopped != "rtol":
        why = {"max_dofs": f"the next level would exceed --max-dofs {max_dofs}",
               "memory": f"the next level would exceed the memory budget {max_memory_gb:g} GB",
               "max_levels": f"{MAX_LEVELS} levels",
               "time": f"the time budget {max_seconds or 0:g} s (a measurable next level was predicted to end past it)",
               "unconverged": "the error estimate's enriched solve, which did not converge in "
                              f"{(last.get('enriched') or {}).get('pcg_iterations')} iterations (a near-incompressible "
                              f"material, ν = {design.material.nu:g}?): the figures' ± are withheld",
               "invalid_mesh": f"the next refinement, whose {last.get('invalid_elements')} elements the projection onto "
                               "the true surface left flat or inverted"}[stopped]
        where = (f"no error estimate at {last['dofs']} dofs" if stopped == "unconverged"
                 else f"worst error estimate {worst:.2%} at {last['dofs']} dofs")
        res["warnings"] = list(res["warnings"]) + [f"--rtol {rtol:g} not reached: {where}; stopped by {why}"]
