"""`torquebench flexure DESIGN.toml`: judge a torque-sensor flexure before machining it.

One design: mesh (gmsh, P2 by default), six load cases with one solver set-up, gauge read-out,
bridge output, stiffness, stress, cross-talk and minimum detectable torque; optional VTU (ParaView)
and off-screen PNG of the strain or von Mises field with the gauges drawn. Each figure carries its
discretisation error estimate: by default goal-oriented adaptive refinement of nested meshes until every
figure's estimate (the enriched-space difference, flexure.enriched) is below --rtol (flexure.adaptive; its
measured effectivity: reports/fem_adaptive.md); ``--error-method levels``: Richardson over three gmsh
mesh levels (flexure.convergence), the cross-check.
``--sweep PARAM=v1,v2,...`` (once or twice): the sensitivity–stiffness–stress trade-off table,
and with ``--png`` the trade-off plot instead of the field picture.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

from userio.errors import InputError
from torquebench.formatting import pm as _pm

HELP = "flexure FEM: sensitivity (mV/V per N·m), stiffness, stress, cross-talk, min torque; sweeps"
EXAMPLES = """\
torquebench flexure
torquebench flexure designs/paper_disc.toml --size medium --png out/disc_strain.png --json
torquebench flexure --sweep spoke_width_mm=3,3.5,4 --order 2 --png out/spoke_sweep.png
torquebench flexure tests/data/fem_reference/step_part.toml --rtol 0.01
torquebench flexure designs/paper_disc.toml --error-method levels
"""
HEADLINE = ("sensitivity_mV_per_V_per_Nm", "torsional_stiffness_Nm_per_rad", "max_von_mises_Pa",
            "safety_factor", "min_detectable_torque_Nm", "gauge_strain_per_Nm", "dofs", "solve_s")


def add_arguments(parser) -> None:
    parser.add_argument("design", nargs="?", type=Path, default=None, metavar="DESIGN.toml",
                        help="flexure design TOML (docs/conventions.md; default: the shipped designs/paper_disc.toml)")
    parser.add_argument("--size", choices=("coarse", "medium", "fine"), default=None,
                        help="mesh size: coarse, medium or fine (default: the file's [mesh] size)")
    parser.add_argument("--order", type=int, choices=(1, 2), default=None,
                        help="element order: 1 = 4-node, 2 = 10-node tetrahedra (default: the file's)")
    parser.add_argument("--vtu", type=Path, default=None, metavar="OUT.vtu",
                        help="write displacement (m), von Mises stress (Pa) and strain fields at rated torque for ParaView; directory created, existing file kept unless --force")
    parser.add_argument("--png", type=Path, default=None, metavar="OUT.png",
                        help="picture of the --field with the gauges (with --sweep: the trade-off plot); directory created, existing file kept unless --force")
    parser.add_argument("--field", choices=("strain", "von_mises"), default="strain",
                        help="field drawn in --png: strain = max shear strain (what ±45° gauges read), von_mises = stress in Pa (default: %(default)s)")
    parser.add_argument("--rtol", type=float, default=None, metavar="R",
                        help="refine until every gauge strain's, the bridge strain's and the stiffness's error "
                             "estimates are below R (relative; default 0.02 for the adaptive method; none for the levels: "
                             "three of them). The levels refine by h/√2 until R is met, the last one fitted under --max-dofs")
    parser.add_argument("--error-method", choices=("adaptive", "levels"), default="adaptive",
                        help="adaptive: goal-oriented refinement of nested meshes, each figure's error estimated "
                             "in the enriched space P2 + cubic surplus (order 2 only; P1 uses the levels); levels: "
                             "Richardson over three gmsh mesh levels, the cross-check (default: %(default)s)")
    parser.add_argument("--max-dofs", type=int, default=None, metavar="N",
                        help="DOF budget of the refinement: stop before a level would exceed N (default: 2,000,000)")
    parser.add_argument("--max-memory-gb", type=float, default=None, metavar="GB",
                        help="memory budget of the adaptive refinement: stop before a level is predicted to "
                             "need more than GB of resident memory (default: 3.0)")
    parser.add_argument("--max-seconds", type=float, default=None, metavar="S",
                        help="time budget of the adaptive refinement: its last level is the one predicted to end "
                             "within S seconds of wall time from the meshing on, and the run says so where --rtol "
                             "is not reached by then (default: none)")
    parser.add_argument("--max-elements", type=float, default=None, metavar="N",
                        help="refuse, before meshing, a mesh estimated above N tetrahedra (default: 500,000, "
                             "about 6 GB for P2 by its estimate; it usually binds before --max-dofs)")
    parser.add_argument("--single-level", action="store_true",
                        help="one mesh level only: faster, but the answers (and sweep rows) carry no error estimate")
    parser.add_argument("--sweep", action="append", metavar="PARAM=v1,v2,...",
                        help="sweep a [geometry] parameter over values in its own unit (e.g. spoke_width_mm=3,4,5); repeat for a 2-D grid, at most twice")
    parser.add_argument("--force", action="store_true", help="replace existing --vtu / --png files")


def _check_outputs(args, design_path: Path, design=None):
    """The output plan (userio.outputs), checked before the (long) analysis runs: --vtu / --png
    never the design or the files it names (STL/STEP, sensor), never replaced without --force."""
    from userio.outputs import Outputs

    for flag, path, suffix in (("--vtu", args.vtu, ".vtu"), ("--png", args.png, ".png")):
        if path is not None and path.suffix.lower() != suffix:
            raise InputError(f"{flag}: {path} must end in {suffix}")
    if args.rtol is not None and args.single_level:
        raise InputError("--rtol: needs the error estimate; drop --single-level")
    if args.rtol is not None and not 1e-6 <= args.rtol <= 0.5:
        raise InputError(f"--rtol: must lie in [1e-6, 0.5] (relative), got {args.rtol:g}")
    if args.max_dofs is not None and args.max_dofs < 1000:
        raise InputError(f"--max-dofs: must be ≥ 1000, got {args.max_dofs}")
    if args.max_memory_gb is not None and not args.max_memory_gb > 0.1:
        raise InputError(f"--max-memory-gb: must be > 0.1, got {args.max_memory_gb:g}")
    if args.max_seconds is not None and not (math.isfinite(args.max_seconds) and args.max_seconds > 0):
        raise InputError(f"--max-seconds: must be a positive number of seconds, got {args.max_seconds:g}")
    if args.sweep:                # its rows carry a two-level indicator (flexure.analysis.sweep): no refinement
        given = [flag for flag, value in (("--rtol", args.rtol), ("--max-dofs", args.max_dofs),
                                          ("--max-memory-gb", args.max_memory_gb), ("--max-seconds", args.max_seconds))
                 if value is not None] + (["--error-method"] if args.error_method != "adaptive" else [])
        if given:
            raise InputError(f"{given[0]}: a setting of one design's refinement, which a sweep does not run (each "
                             "row carries a two-level error indicator); drop it or --sweep")
    if args.max_seconds is not None and (args.error_method != "adaptive" or args.single_level):
        raise InputError("--max-seconds: a budget of the adaptive refinement; drop it, or --error-method levels "
                         "and --single-level")
    if args.max_elements is not None and not args.max_elements >= 100:
        raise InputError(f"--max-elements: must be ≥ 100, got {args.max_elements:g}")
    if args.sweep and args.vtu is not None:
        raise InputError("--vtu: one design at a time; drop --sweep to write fields")
    plan = Outputs(force=args.force)
    plan.input("design file", design_path)
    if design is not None:
        plan.input("geometry.file", design.file_path)
        plan.input("bridge.sensor", design.sensor_path)
    plan.file("--vtu", args.vtu)
    plan.file("--png", args.png)
    return plan.check()


def _print_design(res: dict) -> None:
    m, s = res["mesh"], res["solver"]
    ct = res["crosstalk_percent"]
    leak = res["crosstalk_single_arm_percent"]
    print(f"design: {res['design']}  ({res['design_file']})")
    print(f"material: {res['material']['name']} (E {res['material']['E_Pa'] / 1e9:g} GPa, "
          f"ν {res['material']['nu']:g}, σ_y {res['material']['yield_Pa'] / 1e6:g} MPa)")
    print(f"mesh: {m['n_elements']} P{res['order']} tetrahedra ({res['size']}), {res['dofs']} dofs, "
          f"min dihedral {m['min_dihedral_deg']:.1f}°, worst aspect ratio {m['max_aspect_ratio']:.1f}"
          + (f"; the STL re-meshed, its volume changed by {100 * m['remesh_volume_change']:+.2f} %"
             if m.get("remesh_volume_change") is not None else ""))
    print(f"solver: {s['solver']}; relative residual {s['residual_norm']:.1e}; "
          f"mesh {res['mesh_s']:.1f} s, assembly {res['assemble_s']:.1f} s, solve {res['solve_s']:.1f} s")
    if res["warnings"]:
        print(f"WARNING: {'; '.join(res['warnings'])}"
              + (f": numbers withheld ({res['nan_reason']})" if "nan_reason" in res else ""))
    if "nan_reason" in res:
        print(f"results are not trustworthy: {res['nan_reason']}")
        return
    T = res["rated_torque_Nm"]
    print(f"gauge strain: {res['gauge_strain_per_Nm'] * 1e6:.2f} µε per N·m{_pm(res, 'gauge_strain_per_Nm')} "
          f"({res['gauge_strain_at_0p4Nm'] * 1e6:.2f} µε at 0.4 N·m); arm imbalance "
          f"{res['gauge_arm_imbalance'] * 100:.2f} %")
    print(f"sensitivity: {res['sensitivity_mV_per_V_per_Nm']:.4g} mV/V per N·m"
          f"{_pm(res, 'sensitivity_mV_per_V_per_Nm')} "
          f"({res['output_mV_at_rated']:.3g} mV at {T:g} N·m, {res['excitation_V']:g} V excitation)")
    print(f"torsional stiffness: {res['torsional_stiffness_Nm_per_rad']:.4g} N·m/rad"
          f"{_pm(res, 'torsional_stiffness_Nm_per_rad')}")
    print(f"peak von Mises at {T:g} N·m: {res['max_von_mises_Pa'] / 1e6:.1f} MPa, "
          f"safety factor {res['safety_factor']:.2f}{_pm(res, 'safety_factor')}")
    if "gauge_strain_per_Nm_error_method" in res:
        print(f"error estimates: {res['gauge_strain_per_Nm_error_method']} (gauge strain)")
    if res.get("error_method") == "adaptive":
        arms = res.get("gauge_strains_per_Nm_error_estimate", {})
        per = ", ".join(f"{k} ± {100 * v / abs(res['gauge_strains_per_Nm'][k]):.2g} %" for k, v in arms.items()
                        if res["gauge_strains_per_Nm"].get(k) and v == v) or "withheld"
        print(f"refinement: {len(res['discretization_levels'])} nested level{'' if len(res['discretization_levels']) == 1 else 's'}, stopped by {res['stopped_by']} "
              f"(--rtol {res['rtol']:g}); each gauge: {per}")
    print(f"minimum detectable torque: {res['min_detectable_torque_Nm'] * 1e3:.3g} mN·m (1σ noise), "
          f"{res['min_detectable_torque_enob_Nm'] * 1e3:.3g} mN·m (ENOB resolution)")
    print("cross-talk, % of rated output per N (forces) or per N·m (moments); "
          "single-arm leak in brackets:")
    for k in ct:
        print(f"  {k:<10}{ct[k]:>+10.3g} %  [{leak[k]:.3g} %]")


def run(args) -> int:
    from flexure.analysis import parse_sweep
    from flexure.design import load_design
    from torquebench.io import shipped

    from userio.files import check_input

    path = check_input(args.design or shipped("designs", "paper_disc.toml"), what="flexure design TOML")
    design = load_design(path)
    plan = _check_outputs(args, path, design)
    params = parse_sweep(args.sweep)
    progress = sys.stderr.isatty() or not args.json
    with plan.active():                       # every write (--vtu, --png) obeys the plan
        if params:
            return _sweep(args, path, design, params, progress)
        return _one(args, design, progress)


def _sweep(args, path, design, params, progress) -> int:
    from flexure.analysis import sweep, sweep_plot, sweep_table, sweep_warnings
    from flexure.design import preflight
    from torquebench.io import print_json

    if sum(1 for _ in params) and _count(params) > MAX_DESIGNS:
        raise InputError(f"--sweep: {_count(params)} designs, above the {MAX_DESIGNS} a sweep runs "
                         "(each is a FEM analysis); sweep fewer values")
    import time
    from itertools import product

    keys = [k for k, _ in params]
    combos = list(product(*[v for _, v in params]))
    cost = preflight(design, args.size, args.order, args.max_elements,
                     levels=1 if args.single_level else 2)
    for w in cost["warnings"]:
        print(f"warning: {w}", file=sys.stderr)
    rows = []
    for i, combo in enumerate(combos):       # one design at a time: the first one times the rest
        t0 = time.perf_counter()
        rows += sweep(path, [(k, [v]) for k, v in zip(keys, combo)], args.size, args.order,
                      progress=False, error_estimate=not args.single_level)
        if i == 0 and len(combos) > 1:
            per = time.perf_counter() - t0
            print(f"flexure: sweeping {len(combos)} designs (~{cost['elements_estimate']:.3g} tetrahedra "
                  f"each); the first took {per:.3g} s: estimated total {_human(per * len(combos))}",
                  file=sys.stderr)
    warnings = sweep_warnings(rows, params)
    if args.png is not None:
        sweep_plot(rows, keys, args.png)
    if args.json:
        print_json({"design_file": str(path), "parameters": keys, "rows": rows, "warnings": warnings,
                    "png": str(args.png) if args.png else None})
    else:
        print(sweep_table(rows, keys))
        for w in warnings:
            print(f"warning: {w}")
        if args.png is not None:
            print(f"trade-off plot: {args.png}")
    return 0


MAX_DESIGNS = 10_000


def _count(params) -> int:
    n = 1
    for _, vals in params:
        n *= len(vals)
    return n


def _human(seconds: float) -> str:
    return (f"{seconds:.0f} s" if seconds < 120 else f"{seconds / 60:.1f} min" if seconds < 7200
            else f"{seconds / 3600:.1f} h")


def _one(args, design, progress) -> int:
    from flexure.analysis import analyze
    from flexure.design import preflight
    from torquebench.io import print_json

    for w in preflight(design, args.size, args.order, args.max_elements,
                       levels=1 if args.single_level else 3)["warnings"]:
        print(f"warning: {w}", file=sys.stderr)
    if args.single_level:
        res, fields = analyze(design, args.size, args.order, progress=progress, max_elements=args.max_elements)
    else:
        from flexure.convergence import analyze_design
        res, fields = analyze_design(design, args.size, args.order, rtol=args.rtol, method=args.error_method,
                                     max_dofs=args.max_dofs, max_memory_gb=args.max_memory_gb,
                                     progress=progress and not args.json, max_elements=args.max_elements,
                                     max_seconds=args.max_seconds)
    if args.vtu is not None:
        from flexure.render import write_vtu
        res["vtu"] = str(write_vtu(fields, args.vtu))
    if args.png is not None:
        from flexure.render import render_png
        res["png"] = str(render_png(fields, args.png, field=args.field,
                                    title=f"{design.name}: {args.field.replace('_', ' ')} at "
                                          f"{design.rated_torque_Nm:g} N·m"))
    if args.json:
        print_json(res)
    else:
        _print_design(res)
        for k in ("vtu", "png"):
            if k in res:
                print(f"{k}: {res[k]}")
    return 0
