"""One design → the numbers a sensor designer needs; and a sweep over one or two parameters.

Load cases (all solved with one factorization): a torque M_z on the hub bore and the off-axis
loads F_x, F_y, F_z, M_x, M_y, each a unit wrench at the reference point (0, 0, t/2) carried by a
kinematic rigid coupling of the bore surface (a stiff shaft; ``[loads] coupling = "rigid"``) or
by the statically equivalent traction on it (a compliant hub, ``"distributed"``); the rim is held
(bolt-hole walls, or outer face).

    sensitivity      S = (V_o/V_ex)(T_rated) / T_rated              (exact bridge, mV/V per N·m)
    stiffness        k = T / Θ_z                                     (Θ_z: coupling rotation)
    cross-talk       c_j = 100 · (V_o/V_ex)(unit load j) / (V_o/V_ex)(T_rated)   (% per N or N·m)
    single-arm leak  a_j = 100 · max_i |ε_i(unit load j)| / |ε1 − ε2 + ε3 − ε4|(T_rated)
                     (arms mismatched by δ leak up to ≈ δ · a_j: cross-talk's sensitivity to
                     gauge tolerances; for a symmetric layout c_j → 0 under mesh refinement,
                     what remains of it being discretisation error)
    arm imbalance    (max − min)/mean of |ε_i| under M_z: zero for a symmetric layout in the exact
                     solution, so a measure of the discretisation error at the gauges
    reference strain ε_ref = (ε1 − ε2 + ε3 − ε4)/4 per N·m  (V_o/V_ex ≈ GF ε_ref, full bending)
    min torque       T_min = ε_min(bridge noise budget) / ε_ref
    safety factor    σ_y / max σ_vM at T_rated (element-nodal stresses, not averaged)
"""

from __future__ import annotations

import math
import sys
import time
from dataclasses import dataclass

import numpy as np

from flexure.design import Design, load_design
from userio.errors import InputError
from flexure.gauges import bridge_strains, read_footprint
from flexure.mesh import TET_EDGES
from flexure.post import element_nodal_strains, nodal_average, stress_measures

CASES = ("Mz", "Fx", "Fy", "Fz", "Mx", "My")
CROSSTALK_KEYS = {"Fx": "Fx_per_N", "Fy": "Fy_per_N", "Fz": "Fz_per_N", "Mx": "Mx_per_Nm", "My": "My_per_Nm"}
SEGMENTS = {"coarse": 3, "medium": 5, "fine": 8}


@dataclass
class Fields:
    """What the renderer needs: mesh, rated-torque displacement and nodal fields."""

    mesh: object
    u_rated_m: np.ndarray
    von_mises_Pa: np.ndarray        # nodal average (n,)
    strain_eq: np.ndarray           # nodal max shear strain γ_max/2 (n,) — what ±45° gauges see
    gauges: list
    fixed_nodes: np.ndarray
    load_nodes: np.ndarray


def build_mesh(design: Design, size: str | None = None, order: int | None = None, h_factor: float = 1.0,
               max_elements: float | None = None, curvature_h_factor: float | None = None,
               stl_curvature: bool = False):
    """Mesh of the design (P1/P2), finer at the gauges: a swept or tetgen mesh of the parametric
    profile, or tetgen on the surface of an STL (repaired if need be) or a STEP solid (gmsh).
    ``curvature_h_factor``: the curved faces' resolution as at that level (default ``h_factor``);
    ``stl_curvature``: an STL's curved faces resolved too (meshing.mesh_design_surface)."""
    from flexure.geometry import extrude, load_stl, profile
    from flexure.meshing import MAX_ELEMENTS, mesh_design_surface

    size = size or design.size
    order = order or design.order
    cap = max_elements or MAX_ELEMENTS
    centres = np.array([g.centre_m for g in design.gauges])
    extent = 0.5 * max(g.length_m + g.width_m for g in design.gauges) / math.sqrt(2) * 1.3
    gw = min(min(g.width_m, g.length_m) for g in design.gauges)
    if design.kind == "spoke_disc":
        qs = design.segments_per_quarter or SEGMENTS.get(size, 3)
        poly = profile(design.disc, qs)
        solid = extrude(poly, design.disc.thickness)
        _check_gauges(design, solid)
        return mesh_design_surface(poly, design.disc.thickness, size, centres, extent, design.disc.thickness,
                                   order, gauge_width=gw, mesher=design.mesher, h_factor=h_factor,
                                   max_elements=cap, exact_disc=design.disc, feature_surface=solid,
                                   curvature_h_factor=curvature_h_factor)
    where = f"{design.path}: geometry.file"
    if design.kind == "step":
        from flexure.cad import load_step
        from flexure.meshing import size_field
        surf = load_step(design.file_path, where=where, max_elements=cap,
                         size_for=lambda scale: size_field(size, scale, centres, extent, gw, h_factor,
                                                           curvature_h_factor=curvature_h_factor))
    else:
        surf = load_stl(design.file_path, design.file_unit_m, where=where)
    _check_gauges(design, surf)
    scale = float(np.ptp(surf.points, axis=0).min())
    if design.kind == "step" and design.mesher == "gmsh":     # mesh the exact solid, not its triangles
        from flexure.gmsh_mesh import mesh_step
        from flexure.meshing import MeshResult, mesh_report
        field = size_field(size, scale, centres, extent, gw, h_factor, surface=surf,
                           curvature_h_factor=curvature_h_factor)
        from flexure.meshing import check_cost, surface_area, surface_volume
        check_cost(field, surface_volume(surf), surface_area(surf), cap, where)
        mesh = mesh_step(design.file_path, field, order, where=where)
        return MeshResult(mesh, surf, mesh_report(mesh, size, "gmsh", None, field))
    return mesh_design_surface(surf, None, size, centres, extent, scale, order, gauge_width=gw,
                               mesher=design.mesher, h_factor=h_factor, max_elements=cap,
                               curvature_h_factor=curvature_h_factor, stl_curvature=stl_curvature)


def _check_gauges(design: Design, surface) -> None:
    """Every gauge grid on a face of the solid, and the hold and load radii against the part,
    before meshing (InputError naming the gauge or the design file's key)."""
    from flexure.load_check import check_loads
    from flexure.surface_check import check_gauges

    check_gauges(surface.points, surface.faces, design.gauges, f"{design.path}: gauges")
    check_loads(design, surface)


def _selections(design: Design, mesh):
    """(load node set, fixed node set) on the boundary. The geometric tests are made on the element
    vertices (on the true surface); a P2 mid-edge node belongs to a set when both ends of its edge
    do: straight mid-edge nodes sit a sagitta c²/8R inside a convex face (25 µm for a 3 mm chord on
    a 25 mm rim), and testing their own position left them out of a clamped outer face on coarse
    levels, a boundary condition that changed with the mesh."""
    pts = mesh.points
    r = np.hypot(pts[:, 0], pts[:, 1])
    bnodes = np.zeros(len(pts), bool)
    bnodes[mesh.boundary_nodes()] = True
    if mesh.order == 2:
        vertex = np.zeros(len(pts), bool)
        vertex[mesh.corner_tets] = True
        bnodes_v = bnodes & vertex
    else:
        bnodes_v = bnodes
    tol = 1e-6 * max(float(np.ptp(pts, axis=0).max()), 1e-9)

    def with_mid_edges(chosen: np.ndarray) -> np.ndarray:
        if mesh.order == 2:
            for j, (a, b) in enumerate(TET_EDGES):
                mid = mesh.tets[:, 4 + j]
                chosen[mid[chosen[mesh.tets[:, a]] & chosen[mesh.tets[:, b]] & bnodes[mid]]] = True
        return np.flatnonzero(chosen)

    load = with_mid_edges(bnodes_v & (r <= design.load_radius_max_m + tol))
    if design.fixed == "rim_bolts":
        d = design.disc
        n = d.rim_bolts
        a = 2 * np.pi * np.arange(n) / n + np.pi / n + np.deg2rad(d.phase_deg)
        c = d.rim_bolt_circle_radius * np.column_stack([np.cos(a), np.sin(a)])
        dist = np.sqrt(((pts[:, None, :2] - c[None]) ** 2).sum(-1)).min(1)
        fixed = with_mid_edges(bnodes_v & (dist <= d.rim_bolt_diameter / 2 * 1.02 + tol))
    else:
        fixed = with_mid_edges(bnodes_v & (r >= design.fixed_radius_min_m - tol))
    if len(load) < 3:
        centre = np.round((pts.min(axis=0) + pts.max(axis=0))[:2] / 2 * 1e3, 3).tolist()
        raise InputError(f"{design.path}: loads.load_radius_max_mm: no surface nodes within "
                         f"{design.load_radius_max_m * 1e3:g} mm of the torque axis (the file's z axis "
                         f"through its origin; the part's bounding box is centred at x, y = {centre} mm) "
                         "to carry the load")
    if len(fixed) < 3:
        raise InputError(f"{design.path}: loads.fixed: no surface nodes selected to hold the flexure")
    return load, fixed


#: CG tolerance of the design analysis: on the paper disc 1e-8 and 1e-10 give gauge strains,
#: stiffness and stress that agree to 1e-11 relative, with 15 % fewer iterations.
RTOL = 1e-8
#: swept meshes (flat layers) get the smoothed-aggregation coarse solve: on the paper disc's fine
#: mesh 142 → 69 CG iterations, 27 → 18 s for the torque case (a structured annulus, by contrast,
#: keeps its iterations and only pays the denser set-up: see benchmarks/bench_fem.py).
#: gmsh (the default): on the paper disc at 317k P2 DOFs, 60–81 → 39–46 iterations and about half
#: the CPU time of the six cases (benchmarks/bench_fem.py --only three, --only ladder).
SMOOTHED_COARSE = {"sweep": True, "tetgen": False, "gmsh": True}


def _solve_cases(design: Design, mesh, K, load_nodes, fixed_nodes, ref: np.ndarray, wrench: np.ndarray,
                 x0: np.ndarray | None = None, solver=None, rtol: float | None = None):
    """Displacements U (n, 3, cases) and hub rotations Θ (3, cases) for unit wrenches (cases, 6)
    at ``ref``, with one factorization (direct, below solve.DIRECT_MAX_DOFS) or one AMG hierarchy
    (P2: the p-multigrid) for all cases; ``x0`` (n_q, cases): the iterative solver's initial guess;
    ``solver``: a ``solve.prepared`` solver of this very system (set up already), else one is made.

    coupling "rigid": the bore nodes move as a rigid body (multipoint constraint), Θ its rotation;
    "distributed": the statically equivalent linear traction on the bore faces, Θ its
    work-conjugate mean rotation J⁻¹∫ r × u dA (bc.wrench_traction, bc.mean_rotation)."""
    from flexure import solve as fsolve
    from flexure.bc import Problem, mean_rotation, wrench_traction

    problem = Problem(mesh, design.material).fix(fixed_nodes)
    if design.coupling == "rigid":
        problem.couple_rigid(load_nodes, ref, kind="kinematic")
        system = problem.reduced_system(K)
        fsolve._check_restrained(system)
        B = np.repeat(system.b[:, None], len(wrench), axis=1)
        B[system.ref_slices[0], :] = wrench.T
        if solver is not None:
            q, info = solver(B, x0, rtol or RTOL)
        else:
            q, info = fsolve.solve_reduced(system, B, rtol=rtol or RTOL, smoothed_coarse=SMOOTHED_COARSE[design.mesher],
                                           x0=x0)
        U = np.stack([problem.expand(system, q[:, j]) for j in range(len(wrench))], axis=-1)
        return U, q[system.ref_slices[0]][3:, :], info
    is_load = np.zeros(mesh.n_nodes, bool)
    is_load[load_nodes] = True
    faces = mesh.boundary_faces()
    faces = faces[is_load[faces].all(axis=1)]
    system = problem.reduced_system(K)
    fsolve._check_restrained(system)
    B = np.column_stack([wrench_traction(mesh, faces, ref, w[:3], w[3:]).ravel() for w in wrench])
    B[system.fixed_q] = 0.0                       # fixed dofs hold zero displacement
    if solver is not None:
        q, info = solver(B, x0, rtol or RTOL)
    else:
        q, info = fsolve.solve_reduced(system, B, rtol=rtol or RTOL, smoothed_coarse=SMOOTHED_COARSE[design.mesher],
                                       x0=x0)
    U = q.reshape(mesh.n_nodes, 3, len(wrench))
    return U, np.column_stack([mean_rotation(mesh, faces, U[..., j]) for j in range(len(wrench))]), info


def solved_cases(design: Design, mesh, K, load_nodes, fixed_nodes, ref: np.ndarray, wrench: np.ndarray,
                 x0: np.ndarray | None = None, solver=None, rtol: float | None = None):
    """What ``analyze_mesh`` reads of the load cases, by solving all of them (``_solve_cases``):
    (u of the first case (n, 3), each gauge's reading under each case (g, cases), the hub rotation
    Θ_z of the first case, solver info). flexure.goal_cases gives the same from an adaptive level's
    goal solve (the readings from its gauge duals)."""
    from flexure.fem import stiffness_matrix

    K = stiffness_matrix(mesh, design.material) if K is None else K
    U, theta, info = _solve_cases(design, mesh, K, load_nodes, fixed_nodes, ref, wrench, x0, solver, rtol)
    return U[:, :, 0], read_footprint(design.gauges, mesh, U), float(theta[2, 0]), info


def _sensor_config(design: Design):
    from bridge.config import SensorConfig, load_sensor_config

    if design.sensor_path is not None:
        cfg, _ = load_sensor_config(design.sensor_path)
    else:
        cfg = SensorConfig()
    return cfg.replace(gauge_factor=design.gauge_factor, gauge_resistance_ohm=design.gauge_resistance_ohm,
                       arrangement="full_bending")


def analyze(design: Design, size: str | None = None, order: int | None = None, progress: bool = False,
            h_factor: float = 1.0, max_elements: float | None = None):
    """Mesh (element sizes × ``h_factor``), solve the six load cases, read the gauges → (results
    dict, Fields). One mesh level: flexure.convergence adds the discretisation error estimate."""
    t0 = time.perf_counter()
    mres = build_mesh(design, size, order, h_factor, max_elements)
    mesh_s = time.perf_counter() - t0
    if progress:
        print(f"flexure: mesh {mres.report['n_elements']} P{mres.mesh.order} tetrahedra, {mres.mesh.n_dofs} dofs "
              f"({mesh_s:.1f} s)", file=sys.stderr)
    return analyze_mesh(design, mres, mesh_s, progress)


def _solve_unconverged(info: dict) -> bool:
    """The solve's check: a goal solve with a loose CG (flexure.goals, ``goal_algebraic_limit``) by
    its goals' algebraic error (from the residual and the duals) against its limit, any other by its
    relative residual against solve.RESIDUAL_LIMIT."""
    from flexure import solve as fsolve

    if "goal_algebraic_limit" in info:
        e = info.get("goal_algebraic_error", math.nan)
        return not (math.isfinite(e) and e <= info["goal_algebraic_limit"])
    return not np.isfinite(info["residual_norm"]) or info["residual_norm"] > fsolve.RESIDUAL_LIMIT


def analyze_mesh(design: Design, mres, mesh_s: float = 0.0, progress: bool = False, x0=None, K=None,
                 solver=None, rtol: float | None = None, selections=None, cases=None):
    """``analyze`` on a given mesh (``mres``: meshing.MeshResult; ``mesh_s`` its meshing time):
    the six load cases (``x0``: an initial guess of the solver, (n_q, 6); ``K`` the stiffness matrix
    and ``solver`` a prepared solver of the system, if already made; ``rtol`` the CG tolerance,
    default RTOL; ``selections`` the (load, fixed) node sets if not the design's radius bands on this
    mesh, e.g. flexure.adaptive's nested ones; ``cases`` what gives the load cases' readings, default
    ``solved_cases``), the gauges, the figures → (results dict, Fields)."""
    from bridge.budget import min_detectable_strain
    from bridge.wheatstone import output_ratio
    from flexure import slivers
    from flexure import solve as fsolve
    from flexure.fem import stiffness_matrix

    def say(msg):
        if progress:
            print(f"flexure: {msg}", file=sys.stderr)

    t_all = time.perf_counter() - mesh_s
    mesh = mres.mesh
    load_nodes, fixed_nodes = _selections(design, mesh) if selections is None else selections
    t_mid = 0.5 * (mesh.points[:, 2].min() + mesh.points[:, 2].max())
    ref = np.array([0.0, 0.0, t_mid])
    t0 = time.perf_counter()
    K = stiffness_matrix(mesh, design.material) if K is None and cases is None else K
    assemble_s = time.perf_counter() - t0
    wrench = np.zeros((6, 6))                        # rows: cases; cols: (F, M)
    for i, c in enumerate(CASES):
        wrench[i, {"Fx": 0, "Fy": 1, "Fz": 2, "Mx": 3, "My": 4, "Mz": 5}[c]] = 1.0
    t0 = time.perf_counter()
    u0, readings, theta_z, info = (cases or solved_cases)(design, mesh, K, load_nodes, fixed_nodes, ref, wrench,
                                                          x0, solver, rtol)
    solve_s = time.perf_counter() - t0
    say(f"solved {len(CASES)} load cases ({info['solver']}, {solve_s:.1f} s, residual {info['residual_norm']:.1e})")
    warnings, metrics = fsolve.conditioning_warnings(mesh, design.material)
    warnings = slivers.annotate(warnings, mesh, mres.report)     # any below 10°, explained
    if info.get("condition_estimate", 0.0) > fsolve.COND_LIMIT:
        warnings.append("ill_conditioned")
    if _solve_unconverged(info):
        warnings.append("large_residual")
    repairs = (mres.surface.info.get("repairs") if mres.surface is not None else None) or []
    if repairs:                                    # a repair changes the geometry: say so
        warnings.append(f"the surface was repaired before meshing ({', '.join(repairs)}); check the result")

    eps = bridge_strains(design.gauges, readings)                           # (cases, 4)
    T = design.rated_torque_Nm
    gf = design.gauge_factor
    flagged = any(w in warnings for w in ("ill_conditioned", "large_residual", "near_incompressible"))
    if flagged:         # no bridge output from a flagged solve (its strains may be anything)
        ratio_rated, ratio_unit = math.nan, np.full(len(CASES), math.nan)
    else:
        ratio_rated = float(output_ratio(eps[0] * T, "full_bending", gf, design.gauge_resistance_ohm))
        ratio_unit = output_ratio(eps, "full_bending", gf, design.gauge_resistance_ohm)   # (cases,)
    sens = ratio_rated / T * 1e3
    eps_ref = float((eps[0, 0] - eps[0, 1] + eps[0, 2] - eps[0, 3]) / 4.0)
    crosstalk = {CROSSTALK_KEYS[c]: float(100.0 * ratio_unit[i] / ratio_rated)
                 for i, c in enumerate(CASES) if c != "Mz"}
    # what one arm alone sees of each off-axis load, as % of the rated bridge strain: a bridge
    # whose arms differ by δ (gauge factor, placement) leaks up to δ × this into the output
    rated_bridge_strain = 4.0 * abs(eps_ref) * T
    arm_leak = {CROSSTALK_KEYS[c]: float(100.0 * np.abs(eps[i]).max() / rated_bridge_strain)
                for i, c in enumerate(CASES) if c != "Mz"}
    # a symmetric layout reads |ε| equal on all arms under Mz: the spread is discretisation error
    imbalance = float(np.ptp(np.abs(eps[0])) / np.abs(eps[0]).mean())
    stiffness = float(1.0 / theta_z) if theta_z != 0 else math.nan

    u_rated = u0 * T
    eps_nodes = element_nodal_strains(mesh, u_rated)
    vm_elem, gmax = stress_measures(eps_nodes, design.material)
    max_vm = float(vm_elem.max())

    cfg = _sensor_config(design)
    eps_min_noise = min_detectable_strain(cfg, method="noise")
    eps_min_enob = min_detectable_strain(cfg, method="resolution", n_bits=cfg.enob)
    nan_if = (lambda v: math.nan if flagged else v)
    good_ref = eps_ref > 0
    results = {
        "design": design.name,
        "design_file": str(design.path),
        "rated_torque_Nm": T,
        "sensitivity_mV_per_V_per_Nm": nan_if(sens),
        "output_mV_at_rated": nan_if(ratio_rated * cfg.excitation_V * 1e3),
        "torsional_stiffness_Nm_per_rad": nan_if(stiffness),
        "max_von_mises_Pa": nan_if(max_vm),
        "safety_factor": nan_if(design.material.yield_Pa / max_vm),
        "crosstalk_percent": {k: nan_if(v) for k, v in crosstalk.items()},
        "crosstalk_single_arm_percent": {k: nan_if(v) for k, v in arm_leak.items()},
        "gauge_arm_imbalance": nan_if(imbalance),
        "min_detectable_torque_Nm": nan_if(eps_min_noise / eps_ref if good_ref else math.nan),
        "min_detectable_torque_enob_Nm": nan_if(eps_min_enob / eps_ref if good_ref else math.nan),
        "min_detectable_strain_noise": eps_min_noise,
        "min_detectable_strain_enob": eps_min_enob,
        "gauge_strain_per_Nm": nan_if(eps_ref),
        "gauge_strains_per_Nm": {f"arm{i + 1}": nan_if(float(eps[0, i])) for i in range(4)},
        "gauge_strain_at_0p4Nm": nan_if(eps_ref * 0.4),
        "dofs": int(mesh.n_dofs),
        "solve_s": float(solve_s),
        "assemble_s": float(assemble_s),
        "mesh_s": float(mesh_s),
        "total_s": float(time.perf_counter() - t_all),
        "order": int(mesh.order),
        "size": mres.report["size"],
        "mesh": {k: v for k, v in mres.report.items()},
        "solver": {k: v for k, v in info.items() if k in ("solver", "residual_norm", "condition_estimate",
                                                           "iterations", "dofs", "cg_rtol", "goal_algebraic_error",
                                                           "goal_algebraic_limit")},
        "warnings": warnings,
        "material": {"name": design.material.name, "E_Pa": design.material.E_Pa, "nu": design.material.nu,
                     "yield_Pa": design.material.yield_Pa},
        "excitation_V": cfg.excitation_V,
        "gauge_factor": gf,
        "load_nodes": int(len(load_nodes)),
        "fixed_nodes": int(len(fixed_nodes)),
    }
    if flagged:
        results["nan_reason"] = ", ".join(warnings)
    if not good_ref and not flagged:
        results["nan_reason"] = "bridge output not positive under positive torque (check gauge arms)"
    fields = Fields(mesh, u_rated, nodal_average(mesh, vm_elem), nodal_average(mesh, gmax),
                    design.gauges, fixed_nodes, load_nodes)
    return results, fields


def parse_sweep(specs: list[str]) -> list[tuple[str, list]]:
    """["spoke_width_mm=4,5,6", ...] → [(key, [4.0, 5.0, 6.0]), ...] (one or two parameters)."""
    out = []
    for spec in specs or []:
        if "=" not in spec:
            raise InputError(f"--sweep: expected PARAM=v1,v2,..., got {spec!r}")
        key, vals = spec.split("=", 1)
        key = key.strip()
        try:
            values = [float(v) for v in vals.split(",") if v.strip()]
        except ValueError:
            raise InputError(f"--sweep {key}: values must be numbers, got {vals!r}") from None
        if not values:
            raise InputError(f"--sweep {key}: no values")
        values = [int(v) if v.is_integer() and key in ("spokes", "hub_bolts", "rim_bolts") else v
                  for v in values]
        out.append((key, values))
    if len(out) > 2:
        raise InputError("--sweep: at most two parameters")
    if len(out) == 2 and out[0][0] == out[1][0]:
        raise InputError(f"--sweep: parameter {out[0][0]!r} given twice")
    return out


SWEEP_FIGURES = ("sensitivity_mV_per_V_per_Nm", "torsional_stiffness_Nm_per_rad", "safety_factor",
                 "crosstalk_max_percent")
SWEEP_ERROR_METHOD = ("|difference| between the mesh and one √2-coarser mesh: a discretization-error "
                      "indicator that over-estimates the error of a converging answer")


def sweep(path, params: list[tuple[str, list]], size: str | None = None, order: int | None = None,
          progress: bool = True, error_estimate: bool = True) -> list[dict]:
    """Analyse every combination; each row: parameter values + the headline numbers (or the error)
    and, with ``error_estimate``, each figure's discretization-error indicator (SWEEP_ERROR_METHOD)."""
    from itertools import product

    from flexure.design import load_design as _load

    keys = [k for k, _ in params]
    base = _load(path)
    for k, _ in params:                               # validate names before the long run
        from flexure.design import apply_override
        apply_override(base.raw, k, 1.0)
    combos = list(product(*[v for _, v in params]))
    rows = []
    try:
        from tqdm import tqdm
        it = tqdm(combos, desc="sweep", file=sys.stderr, disable=not progress)
    except ImportError:  # pragma: no cover
        it = combos
    for combo in it:
        overrides = dict(zip(keys, combo))
        row = dict(overrides)
        try:
            d = _load(path, overrides)
            res, _ = analyze(d, size, order)
            row.update({k: res[k] for k in ("sensitivity_mV_per_V_per_Nm", "torsional_stiffness_Nm_per_rad",
                                            "max_von_mises_Pa", "safety_factor", "min_detectable_torque_Nm",
                                            "gauge_strain_per_Nm", "dofs", "solve_s")})
            row["crosstalk_max_percent"] = max(abs(v) for v in res["crosstalk_percent"].values())
            if error_estimate:                        # one coarser level (h × √2): |Δ| per figure
                coarse, _ = analyze(d, size, order, h_factor=math.sqrt(2.0))
                coarse["crosstalk_max_percent"] = max(abs(v) for v in coarse["crosstalk_percent"].values())
                for k in SWEEP_FIGURES:
                    row[f"{k}_error_estimate"] = abs(row[k] - coarse[k])
                    row[f"{k}_error_method"] = SWEEP_ERROR_METHOD
            row["error"] = None
        except InputError as exc:                     # an infeasible combination is a row, not a crash
            row["error"] = str(exc)
        rows.append(row)
    return rows


def sweep_warnings(rows: list[dict], params: list[tuple[str, list]]) -> list[str]:
    """Neighbouring designs (one step along one swept parameter) whose figure differs by less than
    the sum of their discretization-error indicators: that change is mesh noise, not design."""
    keys = [k for k, _ in params]
    index = {tuple(r[k] for k in keys): r for r in rows if not r.get("error")}
    out = []
    for axis, (key, values) in enumerate(params):
        for point, a in index.items():
            i = list(values).index(point[axis])
            if i + 1 >= len(values):
                continue
            b = index.get(point[:axis] + (values[i + 1],) + point[axis + 1:])
            if b is None:
                continue
            for fig in SWEEP_FIGURES:
                ea, eb = a.get(f"{fig}_error_estimate"), b.get(f"{fig}_error_estimate")
                if ea is None or eb is None:
                    continue
                if abs(a[fig] - b[fig]) <= ea + eb:
                    where = ", ".join(f"{k}={v:g}" for k, v in zip(keys, point) if k != key)
                    out.append(f"{fig}: the change from {key}={point[axis]:g} to {values[i + 1]:g}"
                               f"{' (' + where + ')' if where else ''} ({b[fig] - a[fig]:+.3g}) is within "
                               f"the discretization error (±{ea + eb:.2g}); refine the mesh to resolve it")
    return out


def sweep_table(rows: list[dict], keys: list[str]) -> str:
    """Markdown table of a sweep."""
    head = keys + ["mV/V per N·m", "k (N·m/rad)", "σ_vM max (MPa)", "SF", "T_min (mN·m)", "x-talk max (%)"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in rows:
        vals = [f"{r[k]:g}" for k in keys]
        if r.get("error"):
            vals += ["infeasible: " + r["error"].split(": ")[-1]] + [""] * 5
        else:
            vals += [f"{r['sensitivity_mV_per_V_per_Nm']:.4f}", f"{r['torsional_stiffness_Nm_per_rad']:.4g}",
                     f"{r['max_von_mises_Pa'] / 1e6:.1f}", f"{r['safety_factor']:.2f}",
                     f"{r['min_detectable_torque_Nm'] * 1e3:.3g}", f"{r['crosstalk_max_percent']:.2g}"]
        lines.append("| " + " | ".join(vals) + " |")
    return "\n".join(lines)


def sweep_figure(rows: list[dict], keys: list[str]):
    """The trade-off figure of a sweep: sensitivity vs stiffness, colour = safety factor, labels =
    parameters; tick labels that never overlap (flexure.plot_ticks). → matplotlib Figure."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from flexure.plot_ticks import readable_log_ticks

    ok = [r for r in rows if not r.get("error")]
    fig, ax = plt.subplots(figsize=(7, 5))
    if ok:
        x = np.array([r["torsional_stiffness_Nm_per_rad"] for r in ok])
        y = np.array([r["sensitivity_mV_per_V_per_Nm"] for r in ok])
        sf = np.array([r["safety_factor"] for r in ok])
        sc = ax.scatter(x, y, c=sf, cmap="RdYlGn", vmin=0.5, vmax=4, s=60, edgecolor="k")
        fig.colorbar(sc, ax=ax, label="safety factor at rated torque")
        for r, xi, yi in zip(ok, x, y):
            ax.annotate(", ".join(f"{r[k]:g}" for k in keys), (xi, yi), textcoords="offset points",
                        xytext=(4, 4), fontsize=7)
        ax.set_xscale("log")
        ax.set_yscale("log")
        readable_log_ticks(ax.xaxis, x)
        readable_log_ticks(ax.yaxis, y)
    ax.set_xlabel("torsional stiffness (N·m/rad)")
    ax.set_ylabel("sensitivity (mV/V per N·m)")
    ax.set_title("flexure sweep: " + " × ".join(keys) + " (labels)")
    ax.grid(True, which="both", alpha=0.3)
    fig.tight_layout()
    return fig


def sweep_plot(rows: list[dict], keys: list[str], out_png) -> None:
    """``sweep_figure`` written to ``out_png`` (atomic)."""
    import matplotlib.pyplot as plt

    from userio.files import atomic_write

    fig = sweep_figure(rows, keys)
    try:
        atomic_write(out_png, lambda tmp: fig.savefig(tmp, dpi=110, format="png"))
    finally:
        plt.close(fig)


__all__ = ["analyze", "build_mesh", "sweep", "sweep_warnings", "parse_sweep", "sweep_table", "sweep_plot", "sweep_figure",
           "load_design"]
