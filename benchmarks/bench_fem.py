"""FEM benchmarks: our P2 assembly/solve beside scikit-fem, a ≥300k-DOF model, convergence table.

Run from the repo root:  python benchmarks/bench_fem.py [--quick] [--skip-skfem] [--skip-scale] [--skip-report]
                         python benchmarks/bench_fem.py --only three|ladder|skfem-amg [--orders 2,1] [--json-out F]
1. Same tetgen P2 mesh (hollow tube in torsion) in both codes: assembly time (ratio vs scikit-fem,
   the anchor measured in this run), direct solve time, gauge-point strains (relative difference).
2. Scale (in a subprocess, for a clean peak memory): a 329k-DOF P2 annular disc end to end
   (mesh → assemble → rigid coupling + fixed rim → AMG-CG → strains), DOFs, time, peak RSS.
3. Error against run time, P1/P2 × mesh × solver (torquebench/reports/fem.py → reports/).
4. The paper's disc (designs/paper_disc.toml) at the fine size, ≥ 300k P2 DOFs, in a subprocess:
   the whole design analysis (swept mesh → assembly → six load cases with one p-multigrid
   set-up → gauges, stress, cross-talk), time per stage and per load case, peak RSS.
5. (--only three) The paper disc, the thick disc (5 mm, 0.5 mm gauges, no fillets) and that disc as
   an STL part, each at ≥ 300k P2 DOFs with the default mesher (size preset × h_factor), then P1 on
   the same meshes: DOFs, min dihedral, wall and CPU time per stage, CG iterations and residual per
   load case, peak RSS, each in a fresh subprocess.
6. (--only ladder) CG iterations on the paper disc at three mesh sizes (h × 2, √2, 1 of [5]).
7. (--only skfem-amg) scikit-fem P2 + pyamg smoothed aggregation beside ours, same mesh and load case.
"""

from __future__ import annotations

import argparse
import json
import resource
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def tube_mesh(ri, ro, h, hmax, sections=64):
    """tetgen P1 mesh of a hollow cylinder (trimesh annulus surface, quality -q1.6/14°)."""
    import tetgen
    import trimesh

    from flexure.mesh import Mesh

    surf = trimesh.creation.annulus(r_min=ri, r_max=ro, height=h, sections=sections)
    surf.apply_translation((0, 0, h / 2))
    tg = tetgen.TetGen(np.asarray(surf.vertices, float), np.asarray(surf.faces, np.int32))
    nodes, elems, *_ = tg.tetrahedralize(plc=True, quality=True, minratio=1.6, mindihedral=14.0,
                                         maxvolume=hmax ** 3 / (6 * np.sqrt(2)), fixedvolume=True,
                                         quiet=True)
    elems = np.asarray(elems[:, :4], np.int64)
    m = Mesh(np.asarray(nodes, float), elems)
    neg = m.signed_volumes() < 0
    if neg.any():
        elems[neg] = elems[neg][:, [0, 2, 1, 3]]
        m = Mesh(m.points, elems)
    return m


def skfem_side_by_side(hmax=3e-3, sections=40):
    import skfem
    from skfem.models.elasticity import lame_parameters, linear_elasticity

    from flexure.bc import Problem
    from flexure.fem import stiffness_matrix
    from flexure.material import ALUMINIUM_6061_T6 as MAT
    from flexure.mesh import quality, to_quadratic
    from flexure.post import strain_at
    from flexure.solve import solve

    ri, ro, h = 0.004, 0.012, 0.016
    m1 = tube_mesh(ri, ro, h, hmax, sections=sections)
    m2 = to_quadratic(m1)
    q = quality(m1)
    print(f"[1] tube P2 mesh: {m2.n_elements} tets, {m2.n_dofs} DOFs, min dihedral "
          f"{q['min_dihedral_deg']:.1f}°, worst aspect {q['max_aspect_ratio']:.2f}")
    # ours: cold (pattern computed) and warm (pattern cached), best of 2 warm
    t0 = time.perf_counter()
    K = stiffness_matrix(m2, MAT)
    t_ours_cold = time.perf_counter() - t0
    t_ours = min(_timed(lambda: stiffness_matrix(m2, MAT)) for _ in range(2))
    # scikit-fem on the same vertices/tets (its own P2 dofs)
    sm = skfem.MeshTet(m1.points.T.copy(), m1.tets.T.astype(np.int64).copy())
    form = linear_elasticity(*lame_parameters(MAT.E_Pa, MAT.nu))

    def sk_assemble():
        basis = skfem.Basis(sm, skfem.ElementVector(skfem.ElementTetP2()))
        return basis, form.assemble(basis)

    t0 = time.perf_counter()
    basis, K_sk = sk_assemble()
    t_sk = time.perf_counter() - t0
    perm = _perm(basis, sm, m1, m2)
    dK = abs(K - K_sk[perm][:, perm]).max() / abs(K).max()
    print(f"    assembly  ours {t_ours:.2f} s (cold, incl. sparsity pattern: {t_ours_cold:.2f} s)  "
          f"scikit-fem {t_sk:.2f} s  → ours {t_sk / t_ours:.1f}× faster warm, "
          f"{t_sk / t_ours_cold:.1f}× cold   (max |ΔK|/max|K| = {dK:.1e})")
    # torsion: bottom fixed, torque on the top face as the statically equivalent traction
    p = Problem(m2, MAT).fix(m2.select_nodes(lambda x: x[:, 2] < 1e-12))
    p.couple_rigid(m2.select_faces(lambda x: x[:, 2] > h - 1e-12), (0, 0, h), moment_Nm=(0, 0, 1.0),
                   kind="distributed")
    s = solve(p, method="direct", K=K, condition_estimate=False)
    f_sk = np.zeros(K.shape[0])
    f_sk[perm] = p.load_vector()
    D = perm[np.flatnonzero(p.fixed.ravel())]
    t0 = time.perf_counter()
    u_sk = skfem.solve(*skfem.condense(K_sk, f_sk, D=D))
    t_sk_solve = time.perf_counter() - t0
    s_amg = solve(p, method="amg", K=K)
    u_o = np.zeros_like(u_sk)
    u_o[perm] = s.u.ravel()
    print(f"    solve     ours direct {s.info['solve_s']:.2f} s, ours AMG-CG {s_amg.info['solve_s']:.2f} s "
          f"({s_amg.info['iterations']} it, residual {s_amg.info['residual_norm']:.1e}), scikit-fem "
          f"(condense + spsolve) {t_sk_solve:.2f} s;  max |Δu|/max|u| = "
          f"{np.abs(u_o - u_sk).max() / np.abs(u_sk).max():.1e}")
    # gauge points: ±45° on the outer surface at mid-height (just inside the facets)
    ang = np.array([0.1, 1.7, 3.3, 4.9])
    r = ro * np.cos(np.pi / sections) * 0.999
    pts = np.stack([r * np.cos(ang), r * np.sin(ang), np.full(4, 0.4 * h)], axis=1)
    d45 = np.stack([-np.sin(ang), np.cos(ang), np.ones(4)], axis=1) / np.sqrt(2)
    t0 = time.perf_counter()
    eps = strain_at(m2, s.u, pts)
    t_read = time.perf_counter() - t0
    e_ours = np.einsum("ki,kij,kj->k", d45, eps, d45)
    elems = sm.element_finder()(*pts.T)
    e_sk = np.empty(4)
    for k in range(4):
        X = sm.mapping().invF(pts[k][:, None, None], tind=np.array([elems[k]]))[:, 0, :]
        cb = skfem.CellBasis(sm, basis.elem, elements=np.array([elems[k]]), quadrature=(X, np.ones(1)))
        H = cb.interpolate(u_sk).grad[:, :, 0, 0]
        e_sk[k] = d45[k] @ (0.5 * (H + H.T)) @ d45[k]
    G, J = MAT.shear_modulus_Pa, np.pi / 2 * (ro ** 4 - ri ** 4)
    print(f"    gauge ε₄₅ per N·m ours {np.array2string(e_ours, precision=6)}  (read {t_read * 1e3:.1f} ms)")
    print(f"                  scikit-fem {np.array2string(e_sk, precision=6)}  "
          f"max rel diff {np.max(np.abs(e_ours / e_sk - 1)):.1e};  thin-shaft theory T r/(2GJ) = "
          f"{r / (2 * G * J):.6e}")


def _timed(fn):
    t0 = time.perf_counter()
    fn()
    return time.perf_counter() - t0


def _perm(basis, sm, m1, m2):
    nv = m1.n_nodes
    perm = np.empty(m2.n_dofs, dtype=np.int64)
    v = np.arange(nv)
    for c in range(3):
        perm[3 * v + c] = basis.nodal_dofs[c]
    sk = np.sort(sm.edges, axis=0)
    sk_code = sk[0] * nv + sk[1]
    order = np.argsort(sk_code)
    a = m2.tets[:, [0, 1, 0, 0, 1, 2]].ravel().astype(np.int64)
    b = m2.tets[:, [1, 2, 2, 3, 3, 3]].ravel().astype(np.int64)
    code = np.minimum(a, b) * nv + np.maximum(a, b)
    e = order[np.searchsorted(sk_code, code, sorter=order)]
    ed = m2.tets[:, 4:].ravel()
    for c in range(3):
        perm[3 * ed + c] = basis.edge_dofs[c][e]
    return perm


def scale_run(n=(16, 128, 6)) -> dict:
    """End to end on a structured annular disc (P2, curved): rim fixed, bore rigidly coupled, AMG-CG.

    Check: an annulus twisted in its plane has k = 4π G h / (1/r_i² − 1/r_o²) (plane shear).
    """
    from flexure.bc import Problem
    from flexure.fem import stiffness_matrix
    from flexure.material import ALUMINIUM_6061_T6 as MAT
    from flexure.mesh import cylinder_mesh, quality
    from flexure.post import strain_at
    from flexure.solve import solve

    t_start = time.perf_counter()
    ri, ro, h = 0.004, 0.030, 0.008       # a 60 mm disc, 8 mm thick, 8 mm bore
    m2 = cylinder_mesh(ri, ro, h, *n, order=2)
    q = quality(m2)
    t_mesh = time.perf_counter() - t_start
    t0 = time.perf_counter()
    K = stiffness_matrix(m2, MAT)
    t_asm = time.perf_counter() - t0
    r = np.hypot(m2.points[:, 0], m2.points[:, 1])
    p = Problem(m2, MAT).fix(np.flatnonzero(r > ro * (1 - 1e-9)))
    p.couple_rigid(np.flatnonzero(r < ri * (1 + 1e-9)), (0, 0, h / 2), moment_Nm=(0, 0, 1.0))
    s = solve(p, method="amg", K=K, rtol=1e-8)
    ang = np.linspace(0, 2 * np.pi, 8, endpoint=False) + 0.1
    rg = 0.015
    pts = np.stack([rg * np.cos(ang), rg * np.sin(ang), np.full(8, h * 0.999)], axis=1)
    eps = strain_at(m2, s.u, pts)
    d45 = np.stack([np.cos(ang + np.pi / 4), np.sin(ang + np.pi / 4), 0 * ang], axis=1)
    e45 = np.einsum("ki,kij,kj->k", d45, eps, d45)
    total = time.perf_counter() - t_start
    peak_GB = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024 ** 2
    G = MAT.shear_modulus_Pa
    return dict(dofs=m2.n_dofs, elements=m2.n_elements, min_dihedral=q["min_dihedral_deg"],
                mesh_s=t_mesh, assemble_s=t_asm,
                setup_s=s.info.get("setup_s"), solve_s=s.info["solve_s"], iterations=s.info["iterations"],
                residual=s.info["residual_norm"], total_s=total, peak_rss_GB=peak_GB,
                stiffness_Nm_per_rad=1.0 / s.reference[0]["theta_rad"][2],
                stiffness_exact=4 * np.pi * G * h / (1 / ri ** 2 - 1 / ro ** 2),
                e45=float(np.mean(np.abs(e45))), e45_exact=1.0 / (4 * np.pi * G * h * rg ** 2),
                warnings=s.info["warnings"], solver=s.info["solver"])


def paper_disc_torque_only(design, size: str) -> tuple[float, float]:
    """The torque case alone, end to end (mesh → assembly → solve → gauges): (seconds, ε_ref)."""
    from flexure.analysis import _selections, _solve_cases, build_mesh
    from flexure.fem import stiffness_matrix
    from flexure.gauges import bridge_strains, read
    from flexure.post import strain_at

    t0 = time.perf_counter()
    mesh = build_mesh(design, size).mesh
    load, fixed = _selections(design, mesh)
    K = stiffness_matrix(mesh, design.material)
    ref = np.array([0.0, 0.0, 0.5 * design.disc.thickness])
    U, _, _ = _solve_cases(design, mesh, K, load, fixed, ref, np.array([[0, 0, 0, 0, 0, 1.0]]))
    eps = bridge_strains(design.gauges, read(design.gauges, lambda p: strain_at(mesh, U[..., 0], p)))
    return time.perf_counter() - t0, float((eps[0] - eps[1] + eps[2] - eps[3]) / 4)


def paper_disc_run(size: str = "fine") -> dict:
    """`flexure.analysis.analyze` on the shipped paper disc (six load cases), then the torque
    case alone; the numbers and the stage times."""
    from flexure.analysis import analyze
    from flexure.design import load_design

    design = load_design(ROOT / "designs" / "paper_disc.toml")
    t0 = time.perf_counter()
    res, _ = analyze(design, size)
    total = time.perf_counter() - t0
    torque_s, eps_torque = paper_disc_torque_only(design, size)
    return dict(torque_only_s=torque_s, torque_only_strain=eps_torque, strain=res["gauge_strain_per_Nm"],dofs=res["dofs"], elements=res["mesh"]["n_elements"], layers=res["mesh"]["layers"],
                mesh_s=res["mesh_s"], assemble_s=res["assemble_s"], solve_s=res["solve_s"],
                iterations=res["solver"]["iterations"], residual=res["solver"]["residual_norm"],
                total_s=total, peak_rss_GB=resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024 ** 2,
                sensitivity=res["sensitivity_mV_per_V_per_Nm"], warnings=res["warnings"])


def _child(flag: str) -> dict | None:
    out = subprocess.run([sys.executable, __file__, flag], capture_output=True, text=True, cwd=ROOT)
    if out.returncode != 0:
        print(out.stderr[-2000:])
        return None
    return json.loads(out.stdout.strip().splitlines()[-1])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--skip-scale", action="store_true")
    ap.add_argument("--skip-report", action="store_true")
    ap.add_argument("--skip-skfem", action="store_true")
    ap.add_argument("--quick", action="store_true", help="small scikit-fem comparison only (~10 s)")
    ap.add_argument("--skip-paper-disc", action="store_true")
    ap.add_argument("--scale-child", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--paper-disc-child", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--only", choices=("three", "ladder", "skfem-amg"),
                    help="three: the paper disc, the thick disc and an STL part at ≥ 300k P2 DOFs (and P1 "
                         "on the same meshes), each in a fresh subprocess; ladder: CG iterations at 3 mesh "
                         "sizes on the paper disc; skfem-amg: scikit-fem P2 + pyamg beside ours on the paper "
                         "disc's ≥ 300k-DOF mesh")
    ap.add_argument("--orders", default="2,1", help="element orders for --only three|ladder (default %(default)s)")
    ap.add_argument("--json-out", type=Path, help="write the --only results as JSON here")
    ap.add_argument("--three-child", nargs=3, metavar=("NAME", "ORDER", "H_FACTOR"), help=argparse.SUPPRESS)
    ap.add_argument("--skfem-amg-child", help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    if a.three_child:
        name, order, hf = a.three_child
        print(json.dumps(three_run(name, int(order), float(hf) if hf != "-" else None)))
        return 0
    if a.skfem_amg_child:
        print(json.dumps(skfem_amg_run(a.skfem_amg_child)))
        return 0
    if a.only == "skfem-amg":
        r = _child_args(["--skfem-amg-child", "paper_disc"])
        if r is None:
            return 1
        print_skfem_amg(r)
        if a.json_out is not None:
            from userio.files import write_text_atomic
            write_text_atomic(a.json_out, json.dumps(r, indent=1) + "\n")
        return 0
    if a.only:
        return run_only(a.only, a.json_out, tuple(int(o) for o in a.orders.split(",")))
    if a.scale_child:
        print(json.dumps(scale_run()))
        return 0
    if a.paper_disc_child:
        print(json.dumps(paper_disc_run()))
        return 0
    if a.quick:
        skfem_side_by_side(hmax=3e-3, sections=16)
        return 0
    if not a.skip_skfem:
        skfem_side_by_side()
    if not a.skip_scale:
        r = _child("--scale-child")
        if r is None:
            return 1
        print(f"[2] scale: {r['dofs']:,} DOFs P2 ({r['elements']:,} tets, structured annular disc, min "
              f"dihedral {r['min_dihedral']:.1f}°), {r['solver']}:\n    mesh {r['mesh_s']:.1f} s, "
              f"assemble {r['assemble_s']:.1f} s, AMG setup {r['setup_s']:.1f} s, CG {r['solve_s'] - r['setup_s']:.1f} s "
              f"({r['iterations']} it, residual {r['residual']:.1e}); end to end {r['total_s']:.1f} s "
              f"(target < 30 s), peak RSS {r['peak_rss_GB']:.2f} GB (target < 4 GB); "
              f"\n    k = {r['stiffness_Nm_per_rad']:.5g} N·m/rad (annulus plane-shear theory "
              f"{r['stiffness_exact']:.5g}), ε₄₅ at r = 15 mm {r['e45']:.5g} (theory {r['e45_exact']:.5g}) "
              f"per N·m; warnings {r['warnings']}")
    if not a.skip_paper_disc:
        r = _child("--paper-disc-child")
        if r is None:
            return 1
        n_cases = len(r["iterations"]) if isinstance(r["iterations"], list) else 1
        print(f"[4] paper disc (designs/paper_disc.toml, fine): {r['dofs']:,} DOFs P2 ({r['elements']:,} tets, "
              f"{r['layers']} layers): mesh {r['mesh_s']:.1f} s, assemble {r['assemble_s']:.1f} s, "
              f"{n_cases} load cases {r['solve_s']:.1f} s ({r['solve_s'] / n_cases:.1f} s each, iterations "
              f"{r['iterations']}, residual {r['residual']:.1e}); whole analysis {r['total_s']:.1f} s; "
              f"the torque case alone end to end {r['torque_only_s']:.1f} s (target < 30 s; its ε_ref "
              f"{r['torque_only_strain']:.6g} vs {r['strain']:.6g} in the six-case run); "
              f"peak RSS {r['peak_rss_GB']:.2f} GB (target < 4 GB); "
              f"{r['sensitivity']:.4f} mV/V per N·m; warnings {r['warnings']}")
    if not a.skip_report:
        from torquebench.reports.fem import build, observed_orders, study  # noqa: F401

        t0 = time.perf_counter()
        paths = build(ROOT / "reports")
        print(f"[3] convergence study written to {', '.join(str(p.relative_to(ROOT)) for p in paths)} "
              f"in {time.perf_counter() - t0:.1f} s")
        print((ROOT / "reports" / "fem_convergence.md").read_text().split("\n\n")[2])
    return 0



# --------------------------------------------------------------------------------------------
# [5] three geometries at ≥ 300k P2 DOFs (--only three)

#: mesh settings (size preset, h_factor) that give ≥ 300k P2 DOFs on each geometry with the
#: default (gmsh) mesher; the DOF counts are printed and checked in the run.
THREE_SIZES = {"paper_disc": ("fine", 0.95), "thick_disc": ("fine", 1.05), "stl_part": ("fine", 0.88)}
MIN_DOFS = 300_000


def thick_disc_text() -> str:
    """The issue's thick disc: the paper disc at 5 mm, no fillets, 0.5 × 0.5 mm gauges (as
    tests/test_fem_thick_disc.py builds it)."""
    t = (ROOT / "designs" / "paper_disc.toml").read_text()
    for a, b in (("thickness_mm = 2.2 ", "thickness_mm = 5.0 "), ("fillet_radius_mm = 1.5 ", "fillet_radius_mm = 0.0 "),
                 ("grid_length_mm = 1.5", "grid_length_mm = 0.5"), ("grid_width_mm = 1.5", "grid_width_mm = 0.5"),
                 ('sensor = "../sensors/paper_sensor.toml"', f'sensor = "{ROOT / "sensors" / "paper_sensor.toml"}"')):
        t = t.replace(a, b)
    return t


def three_designs(work: Path) -> dict:
    """{name: Design}: the paper disc, the thick disc, and the thick disc as an STL part (its
    surface exported with trimesh and read back as ``kind = "stl"``, held at the outer face)."""
    import trimesh

    from flexure.design import load_design
    from flexure.geometry import spoke_disc_surface

    work.mkdir(parents=True, exist_ok=True)
    (work / "thick.toml").write_text(thick_disc_text())
    thick = load_design(work / "thick.toml")
    surf = spoke_disc_surface(thick.disc, 3)
    trimesh.Trimesh(surf.points * 1e3, surf.faces, process=False).export(work / "thick.stl")
    gauges = "".join(f"[[gauges.gauge]]\ncentre_mm = {[float(x) * 1e3 for x in g.centre_m]}\n"
                     f"axis = {list(map(float, g.axis))}\narm = {g.arm}\n" for g in thick.gauges)
    (work / "stl.toml").write_text(
        '[geometry]\nkind = "stl"\nfile = "thick.stl"\n[gauges]\ngrid_length_mm = 0.5\n'
        f'grid_width_mm = 0.5\n{gauges}[loads]\nrated_torque_Nm = 2.0\nload_radius_max_mm = 4.004\n'
        'fixed_radius_min_mm = 29.97\n[mesh]\nsize = "coarse"\n')
    return {"paper_disc": load_design(ROOT / "designs" / "paper_disc.toml"), "thick_disc": thick,
            "stl_part": load_design(work / "stl.toml")}


def _cpu_s() -> float:
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def three_run(name: str, order: int = 2, h_factor: float | None = None) -> dict:
    """One geometry end to end as `flexure.analysis.analyze` runs it (its own stage functions:
    mesh → assembly → constraints + preconditioner set-up → six load cases → gauges, stresses),
    with the wall and CPU time of every stage, CG iterations and residual per load case."""
    from flexure.analysis import CASES, _selections, _solve_cases, build_mesh
    from flexure.fem import stiffness_matrix
    from flexure.gauges import bridge_strains, read
    from flexure.post import element_nodal_strains, nodal_average, strain_at, stress_from_strain, von_mises

    design = three_designs(Path("/tmp") / f"bench_fem_three_{name}")[name]
    size, hf = THREE_SIZES[name]
    hf = hf if h_factor is None else h_factor
    stages, t_all, c_all = {}, time.perf_counter(), _cpu_s()

    def stage(key, t0, c0):
        stages[key] = dict(wall_s=time.perf_counter() - t0, cpu_s=_cpu_s() - c0)

    t0, c0 = time.perf_counter(), _cpu_s()
    mres = build_mesh(design, size, order, hf, max_elements=5e6)
    mesh = mres.mesh
    stage("mesh", t0, c0)
    load, fixed = _selections(design, mesh)
    t0, c0 = time.perf_counter(), _cpu_s()
    K = stiffness_matrix(mesh, design.material)
    stage("assembly", t0, c0)
    wrench = np.zeros((6, 6))
    for i, c in enumerate(CASES):
        wrench[i, {"Fx": 0, "Fy": 1, "Fz": 2, "Mx": 3, "My": 4, "Mz": 5}[c]] = 1.0
    t_mid = 0.5 * (mesh.points[:, 2].min() + mesh.points[:, 2].max())
    t0, c0 = time.perf_counter(), _cpu_s()
    U, theta, info = _solve_cases(design, mesh, K, load, fixed, np.array([0.0, 0.0, t_mid]), wrench)
    stage("solve", t0, c0)
    t0, c0 = time.perf_counter(), _cpu_s()
    eps = bridge_strains(design.gauges, read(design.gauges, lambda p: strain_at(mesh, U, p)))
    en = element_nodal_strains(mesh, U[:, :, 0] * design.rated_torque_Nm)
    vm = von_mises(stress_from_strain(en, design.material))
    nodal_average(mesh, vm)
    stage("post", t0, c0)
    cases_s = info.get("case_s", [])
    return dict(name=name, order=order, size=size, h_factor=hf, dofs=int(mesh.n_dofs),
                elements=int(mesh.n_elements), mesher=mres.report.get("mesher"),
                min_dihedral_deg=float(mres.report.get("min_dihedral_deg", np.nan)),
                n_slivers=mres.report.get("n_slivers"), stages=stages,
                setup_s=info.get("setup_s"), case_s=cases_s, cg_s=info.get("cg_s"), cases=list(CASES),
                iterations=info.get("iterations"), case_residuals=info.get("case_residuals"),
                solver=info.get("solver"), amg_levels=info.get("amg_levels"),
                operator_complexity=info.get("operator_complexity"),
                total_wall_s=time.perf_counter() - t_all, total_cpu_s=_cpu_s() - c_all,
                peak_rss_GB=resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024 ** 2,
                strain_per_Nm=float((eps[0, 0] - eps[0, 1] + eps[0, 2] - eps[0, 3]) / 4),
                stiffness_Nm_per_rad=float(1.0 / theta[2, 0]))


def print_three(r: dict) -> None:
    st = r["stages"]
    six = r["cg_s"] + (r["setup_s"] or 0.0)
    solve = st["solve"]["wall_s"]
    print(f"  {r['name']} P{r['order']} ({r['size']}, h × {r['h_factor']:g}, {r['mesher']}): {r['dofs']:,} DOFs, "
          f"{r['elements']:,} tets, min dihedral {r['min_dihedral_deg']:.1f}°, {r['n_slivers']} slivers < 5°")
    print("    stage wall/CPU s: " + ", ".join(f"{k} {v['wall_s']:.1f}/{v['cpu_s']:.1f}" for k, v in st.items())
          + f"; of the solve: constraints {st['solve']['wall_s'] - six:.1f}, preconditioner set-up "
          f"{r['setup_s']:.1f}")
    if r["case_s"]:
        print("    per case: " + ", ".join(f"{c} {t:.1f} s {it} it {res:.0e}" for c, t, it, res in
                                            zip(r["cases"], r["case_s"], r["iterations"], r["case_residuals"])))
    else:
        print(f"    six cases in one CG ({r['cg_s']:.1f} s): " + ", ".join(
            f"{c} {it} it {res:.0e}" for c, it, res in zip(r["cases"], r["iterations"], r["case_residuals"])))
    print(f"    six cases (constraints + set-up + CG) {solve:.1f} s wall {st['solve']['cpu_s']:.1f} s CPU "
          f"(target ≤ 60 s), end to end {r['total_wall_s']:.1f} s wall "
          f"{r['total_cpu_s']:.1f} s CPU, peak RSS {r['peak_rss_GB']:.2f} GB (target ≤ 3 GB); "
          f"ε_ref {r['strain_per_Nm']:.5g} per N·m, k {r['stiffness_Nm_per_rad']:.5g} N·m/rad")


def run_only(which: str, json_out: Path | None, orders=(2, 1)) -> int:
    """--only three | ladder: each run in a fresh subprocess (clean peak RSS), printed as it ends."""
    runs = []
    if which == "three":
        todo = [(g, o, "-") for o in orders for g in THREE_SIZES]
        print(f"[5] three geometries, ≥ {MIN_DOFS:,} P2 DOFs, the default mesher; P1 on the same meshes "
              "(timings on a shared, loaded 2-core machine: pessimistic)")
    else:
        hf0 = THREE_SIZES["paper_disc"][1]
        todo = [("paper_disc", o, f"{hf0 * f:.3g}") for o in orders for f in (2.0, 1.41, 1.0)]
        print("[6] mesh-refinement ladder on the paper disc: CG iterations at 3 sizes")
    for name, order, hf in todo:
        r = _child_args(["--three-child", name, str(order), hf])
        if r is None:
            return 1
        print_three(r)
        runs.append(r)
    if which == "three":
        small = [r["name"] for r in runs if r["order"] == 2 and r["dofs"] < MIN_DOFS]
        if small:
            print(f"    below {MIN_DOFS:,} P2 DOFs: {small} (lower THREE_SIZES' h_factor)")
    if json_out is not None:
        from userio.files import write_text_atomic
        write_text_atomic(json_out, json.dumps(runs, indent=1) + "\n")
        print(f"    written {json_out}")
    return 0


def _child_args(args: list[str]) -> dict | None:
    out = subprocess.run([sys.executable, __file__, *args], capture_output=True, text=True, cwd=ROOT)
    if out.returncode != 0:
        print(out.stderr[-3000:])
        return None
    return json.loads(out.stdout.strip().splitlines()[-1])


def skfem_amg_run(name: str = "paper_disc") -> dict:
    """Ours against scikit-fem P2 + pyamg on the same straight-sided P2 mesh (the geometry's
    THREE_SIZES mesh, its corner tetrahedra): torque M_z as the statically equivalent traction on
    the bore, bolt-hole walls fixed; assembly and solve time of each, iterations, the gauge strain."""
    import pyamg
    import skfem
    from skfem.models.elasticity import lame_parameters, linear_elasticity

    from flexure.analysis import _selections, build_mesh
    from flexure.bc import Problem
    from flexure.fem import rigid_body_modes, stiffness_matrix
    from flexure.gauges import bridge_strains, read
    from flexure.mesh import to_linear, to_quadratic
    from flexure.post import strain_at
    from flexure.solve import solve

    design = three_designs(Path("/tmp") / f"bench_fem_skfem_{name}")[name]
    size, hf = THREE_SIZES[name]
    m1 = to_linear(build_mesh(design, size, 1, hf, max_elements=5e6).mesh)
    m2 = to_quadratic(m1)
    load, fixed = _selections(design, m2)
    faces = m2.boundary_faces()
    is_load = np.zeros(m2.n_nodes, bool)
    is_load[load] = True
    faces = faces[is_load[faces].all(axis=1)]
    ref = (0.0, 0.0, 0.5 * (m2.points[:, 2].min() + m2.points[:, 2].max()))
    out = dict(name=name, dofs=int(m2.n_dofs), elements=int(m2.n_elements))

    def gauge(u):
        eps = bridge_strains(design.gauges, read(design.gauges, lambda p: strain_at(m2, u, p)))
        return float((eps[0] - eps[1] + eps[2] - eps[3]) / 4)

    t0, c0 = time.perf_counter(), _cpu_s()
    K = stiffness_matrix(m2, design.material)
    out["ours_assembly"] = dict(wall_s=time.perf_counter() - t0, cpu_s=_cpu_s() - c0)
    p = Problem(m2, design.material).fix(fixed)
    p.couple_rigid(faces, ref, moment_Nm=(0, 0, 1.0), kind="distributed")
    t0, c0 = time.perf_counter(), _cpu_s()
    s = solve(p, method="amg", K=K, rtol=1e-8, condition_estimate=False)
    out["ours_solve"] = dict(wall_s=time.perf_counter() - t0, cpu_s=_cpu_s() - c0)
    out.update(ours_iterations=s.info["iterations"], ours_residual=s.info["residual_norm"],
               ours_setup_s=s.info["setup_s"], ours_strain=gauge(s.u), ours_solver=s.info["solver"])
    f = p.load_vector()
    del K, s
    # scikit-fem: its own P2 assembly on the same vertices and tetrahedra, pyamg SA on its system
    t0, c0 = time.perf_counter(), _cpu_s()
    sm = skfem.MeshTet(m1.points.T.copy(), m1.tets.T.astype(np.int64).copy())
    basis = skfem.Basis(sm, skfem.ElementVector(skfem.ElementTetP2()))
    K_sk = linear_elasticity(*lame_parameters(design.material.E_Pa, design.material.nu)).assemble(basis)
    out["skfem_assembly"] = dict(wall_s=time.perf_counter() - t0, cpu_s=_cpu_s() - c0)
    perm = _perm(basis, sm, m1, m2)
    f_sk = np.zeros(K_sk.shape[0])
    f_sk[perm] = f
    B_sk = np.zeros((K_sk.shape[0], 6))
    B_sk[perm] = rigid_body_modes(m2.points)
    D = perm[np.flatnonzero(p.fixed.ravel())]
    t0, c0 = time.perf_counter(), _cpu_s()
    A, b, x, I = skfem.condense(K_sk, f_sk, D=D)
    ml = pyamg.smoothed_aggregation_solver(A.tocsr(), B=B_sk[I], symmetry="hermitian")
    setup = time.perf_counter() - t0
    res: list = []
    x[I] = ml.solve(b, tol=1e-8, accel="cg", maxiter=3000, residuals=res)
    out["skfem_solve"] = dict(wall_s=time.perf_counter() - t0, cpu_s=_cpu_s() - c0)
    out.update(skfem_setup_s=setup, skfem_iterations=len(res) - 1,
               skfem_residual=float(np.linalg.norm(b - A @ x[I]) / np.linalg.norm(b)),
               skfem_strain=gauge(x[perm].reshape(-1, 3)),
               peak_rss_GB=resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024 ** 2)
    return out


def print_skfem_amg(r: dict) -> None:
    o = r["ours_assembly"]["wall_s"] + r["ours_solve"]["wall_s"]
    k = r["skfem_assembly"]["wall_s"] + r["skfem_solve"]["wall_s"]
    oc = r["ours_assembly"]["cpu_s"] + r["ours_solve"]["cpu_s"]
    kc = r["skfem_assembly"]["cpu_s"] + r["skfem_solve"]["cpu_s"]
    print(f"[7] {r['name']}, the same straight-sided P2 mesh ({r['dofs']:,} DOFs), torque as bore traction, "
          f"one load case, CG to 1e-8:")
    print(f"    ours:       assembly {r['ours_assembly']['wall_s']:.1f} s, solve {r['ours_solve']['wall_s']:.1f} s "
          f"(set-up {r['ours_setup_s']:.1f} s, {r['ours_iterations']} it, residual {r['ours_residual']:.1e}); "
          f"{o:.1f} s wall {oc:.1f} s CPU")
    print(f"    scikit-fem: assembly {r['skfem_assembly']['wall_s']:.1f} s, pyamg SA solve {r['skfem_solve']['wall_s']:.1f} s "
          f"(set-up {r['skfem_setup_s']:.1f} s, {r['skfem_iterations']} it, residual {r['skfem_residual']:.1e}); "
          f"{k:.1f} s wall {kc:.1f} s CPU")
    print(f"    ours / scikit-fem time: {o / k:.2f} wall, {oc / kc:.2f} CPU; gauge ε_ref per N·m ours "
          f"{r['ours_strain']:.6g}, scikit-fem {r['skfem_strain']:.6g} (relative difference "
          f"{abs(r['ours_strain'] / r['skfem_strain'] - 1):.1e}); peak RSS {r['peak_rss_GB']:.2f} GB")


if __name__ == "__main__":
    sys.exit(main())
