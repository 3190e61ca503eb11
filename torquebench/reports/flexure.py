"""Flexure report: the paper's disc analysed under refinement, against the paper's statements,
the two meshers side by side, a beam-theory check, and a spoke width × thickness sweep.

Writes reports/flexure.md, flexure_strain.png (the paper's Fig. 1 right, our disc),
flexure_von_mises.png and flexure_sweep.png. Takes a few minutes (the fine P2 run is 300k DOFs).
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

SIZES = ("coarse", "medium", "fine")
SWEEP = [("spoke_width_mm", [3.0, 3.5, 4.5]), ("thickness_mm", [1.8, 2.2, 3.0])]



def _its(r: dict) -> int:
    """CG iterations of the torque case (the first)."""
    it = r["solver"]["iterations"]
    return it[0] if isinstance(it, list) else it


def _row(label: str, r: dict) -> str:
    ct = r["crosstalk_percent"]
    return (f"| {label} | {r['dofs']:,} | {r['mesh']['n_elements']:,} | {r['mesh']['min_dihedral_deg']:.1f} | "
            f"{_its(r)} | {r['total_s']:.1f} | {r['gauge_strain_per_Nm'] * 1e6:.2f} | {r['sensitivity_mV_per_V_per_Nm']:.4f} | "
            f"{r['torsional_stiffness_Nm_per_rad']:.0f} | {r['max_von_mises_Pa'] / 1e6:.1f} | "
            f"{r['gauge_arm_imbalance'] * 100:.2f} | {ct['Mx_per_Nm']:+.3f} | {ct['My_per_Nm']:+.3f} | "
            f"{ct['Fz_per_N']:+.4f} |")


HEAD = ("| run | DOFs | elements | min dihedral (°) | CG iterations (Mz) | time (s) | ε_ref (µε/N·m) | mV/V per N·m | "
        "k (N·m/rad) | σ_vM max (MPa) | arm imbalance (%) | Mx (%/N·m) | My (%/N·m) | Fz (%/N) |\n"
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")


def _beam_check():
    """designs/beam_check.toml against flexure.beam's guided-spoke model (as the tests do)."""
    from flexure.analysis import analyze
    from flexure.beam import guided_spokes
    from flexure.design import load_design
    from torquebench.io import shipped

    d = load_design(shipped("designs", "beam_check.toml"))
    disc = d.disc
    k_beam, eps_beam = guided_spokes(disc.hub_radius, disc.rim_inner_radius, disc.spoke_width, disc.thickness,
                                     disc.spokes, d.material, gauge_size_m=d.gauges[0].length_m)
    rows = []
    for size in ("coarse", "medium"):
        r, _ = analyze(d, size)
        rows.append((size, r["dofs"], r["gauge_strain_per_Nm"] / eps_beam, r["torsional_stiffness_Nm_per_rad"] / k_beam))
    return eps_beam, k_beam, rows


def _stiffness_paragraph() -> str:
    """How the paper disc's stiffness and gauge strain converge, from the stored levels
    (tests/data/fem_reference/levels.json, made by benchmarks/fem_levels.py)."""
    import json

    from flexure.convergence import estimate_from_levels

    data = json.loads((Path(__file__).resolve().parents[2] / "tests" / "data" / "fem_reference" / "levels.json").read_text())
    levels = [lv for lv in data["fine"]["paper_disc"] if lv["h_factor"] <= 1.0 + 1e-9][::2]   # × 1, 0.71, 0.5
    levels.append(data["fine"]["paper_disc"][-1])                                              # × 0.42
    k, eps = "torsional_stiffness_Nm_per_rad", "gauge_strain_per_Nm"
    ref = data["references"]["paper_disc"][k]
    answer = data["levels"]["paper_disc"][-1][k]
    est = estimate_from_levels(data["levels"]["paper_disc"], k, 2)[0]
    return ("The torsional stiffness converges slowly: the rigid bore coupling and the clamped bolt-hole walls "
            "meet the free faces at sharp edges (stress singularities, energy error ~ h^(2λ), λ ≈ 0.5), and the "
            "stiffness still falls at the finest level computed (coarse size × "
            + ", × ".join(f"{lv['h_factor']:.2g}" for lv in levels) + ": "
            + ", ".join(f"{lv[k]:.0f}" for lv in levels) + " N·m/rad at "
            + ", ".join(f"{lv['dofs'] / 1e3:.0f}k" for lv in levels) + " DOFs). Its limit lies between the finest "
            f"level and the order-1 extrapolation: {ref['value']:.0f} ± {ref['allowance']:.0f} N·m/rad "
            "(tests/data/fem_reference/levels.json, `benchmarks/fem_levels.py`). `torquebench flexure` reports "
            f"the stiffness as value ± its estimate ({answer:.0f} ± {est / answer:.1%} on the default levels, "
            f"against a distance of {abs(answer - ref['value']) / ref['value']:.2%} ± "
            f"{ref['allowance'] / ref['value']:.2%} to that limit). The gauge strain settles ("
            + ", ".join(f"{lv[eps] * 1e6:.2f}" for lv in levels) + " µε/N·m at the same sizes).\n")


def build(out_dir: Path) -> list[Path]:
    from bridge.chain import PAPER_STRAIN_PER_NM
    from flexure.analysis import analyze, sweep, sweep_plot, sweep_table
    from flexure.design import load_design
    from flexure.render import render_png
    from torquebench.io import shipped
    from torquebench.reports import load_1min
    from userio.files import write_text_atomic

    out_dir = Path(out_dir)
    load0 = load_1min()
    path = shipped("designs", "paper_disc.toml")
    design = load_design(path)
    runs, fields = {}, None
    for size in SIZES:
        print(f"report flexure: paper_disc P2 {size}", file=sys.stderr)
        runs[size], f = analyze(design, size)
        if size == "coarse":
            fields = f
    print("report flexure: tetgen mesher, P1", file=sys.stderr)
    from dataclasses import replace
    tet = {s: analyze(replace(design, mesher="tetgen"), s)[0] for s in ("coarse", "medium")}
    p1 = analyze(design, "medium", order=1)[0]
    dist = analyze(replace(design, coupling="distributed"), "medium")[0]
    strain_png = render_png(fields, out_dir / "flexure_strain.png", "strain",
                            title=f"paper_disc: max shear strain at {design.rated_torque_Nm:g} N·m")
    vm_png = render_png(fields, out_dir / "flexure_von_mises.png", "von_mises",
                        title=f"paper_disc: von Mises stress at {design.rated_torque_Nm:g} N·m")
    eps_beam, k_beam, beam_rows = _beam_check()
    print("report flexure: sweep", file=sys.stderr)
    rows = sweep(path, SWEEP, "coarse", 2, progress=True)
    keys = [k for k, _ in SWEEP]
    sweep_png = out_dir / "flexure_sweep.png"
    sweep_plot(rows, keys, sweep_png)

    fine, coarse = runs["fine"], runs["coarse"]
    eps = fine["gauge_strain_per_Nm"]
    T = fine["rated_torque_Nm"]
    L = ["# Flexure: the paper's torque-sensor disc before machining\n",
         "Generated by `torquebench report --only flexure` (torquebench/reports/flexure.py) from "
         "`designs/paper_disc.toml`: a 4-spoke 6061-T6 disc, 60 mm across, 2.2 mm thick, spokes 3.5 mm "
         "wide, one ±45° gauge (1.5 × 1.5 mm grid) on each spoke's top face at mid-length, a full "
         "bridge (GF 2, 1 kΩ, 5 V) read by the paper's ADC chain (`sensors/paper_sensor.toml`). The "
         "torque enters through a rigid coupling of the bore wall; the rim is held at its eight bolt "
         "holes. Six load cases (Mz and the off-axis Fx, Fy, Fz, Mx, My) share one solver set-up. "
         "The paper gives no dimensions: these are ours (see the design file).\n",
         f"**Headline:** the paper's disc (our dimensions) reads {eps * 1e6:.1f} µε per N·m at its gauges, "
         f"{fine['sensitivity_mV_per_V_per_Nm']:.4f} mV/V per N·m, with a torsional stiffness of "
         f"{fine['torsional_stiffness_Nm_per_rad']:.0f} N·m/rad and a safety factor of {fine['safety_factor']:.2f} "
         f"at {T:g} N·m (P2, fine mesh; coarse to fine moves the strain by "
         f"{abs(coarse['gauge_strain_per_Nm'] / eps - 1) * 100:.2f} %)\n",
         "## Refinement (P2 tetrahedra, gmsh: graded isotropic mesh of the exact solid)\n", HEAD,
         *[_row(f"P2 {s}", runs[s]) for s in SIZES],
         _row("P2 coarse, tetgen", tet["coarse"]), _row("P2 medium, tetgen", tet["medium"]),
         _row("P2 medium, distributed hub load", dist), _row("P1 medium", p1), "",
         f"Times are wall seconds on {os.cpu_count()} cores at a 1-minute load of {load0} (start) and "
         f"{load_1min()} (end) of this build: compare rows, not machines.\n",
         f"Gauge strain changes by {abs(coarse['gauge_strain_per_Nm'] / eps - 1) * 100:.2f} % from coarse "
         f"to fine and by {abs(runs['medium']['gauge_strain_per_Nm'] / eps - 1) * 100:.2f} % from medium to "
         "fine. Cross-talk of this symmetric layout is mesh error and falls with refinement, as the "
         "arm imbalance (spread of |ε| over the four arms under Mz, zero in the exact solution) does.\n",
         "Meshers: gmsh (the default) meshes the exact OpenCASCADE solid (true circles and fillets, "
         "so the geometry converges with the mesh) with the gauge size field; tetgen grades from the "
         "closed polygonal surface (3, 5, 8 segments per quarter circle for coarse, medium, fine) under "
         "a volume bound. On the medium size they read the same gauge strain to "
         f"{abs(tet['medium']['gauge_strain_per_Nm'] / runs['medium']['gauge_strain_per_Nm'] - 1) * 100:.2f} % "
         f"(CG iterations: tetgen {_its(tet['medium'])}, gmsh {_its(runs['medium'])}); on the coarse "
         f"size tetgen leaves elements down to {tet['coarse']['mesh']['min_dihedral_deg']:.1f}° "
         + ("(flagged `sliver_elements` in the warnings), " if tet["coarse"]["warnings"] else "")
         + f"while gmsh's smallest dihedral angle is {coarse['mesh']['min_dihedral_deg']:.1f}°. "
         + "Loading the bore by the statically "
         "equivalent traction instead of a rigid shaft lowers the stiffness by "
         f"{(1 - dist['torsional_stiffness_Nm_per_rad'] / runs['medium']['torsional_stiffness_Nm_per_rad']) * 100:.1f} % "
         "(the hub's own compliance) and moves the gauge strain by "
         f"{(dist['gauge_strain_per_Nm'] / runs['medium']['gauge_strain_per_Nm'] - 1) * 100:+.2f} %. "
         "P1 locks (too stiff, strains too small): the pipeline uses P2.\n",
         "## Numbers a designer needs (P2 fine)\n",
         "| quantity | value |\n|---|---|",
         f"| gauge strain ε_ref = (ε1 − ε2 + ε3 − ε4)/4 | {eps * 1e6:.2f} µε per N·m |",
         f"| bridge sensitivity | {fine['sensitivity_mV_per_V_per_Nm']:.4f} mV/V per N·m "
         f"({fine['output_mV_at_rated']:.2f} mV at {T:g} N·m) |",
         f"| torsional stiffness | {fine['torsional_stiffness_Nm_per_rad']:.0f} N·m/rad |",
         f"| peak von Mises at {T:g} N·m / safety factor | {fine['max_von_mises_Pa'] / 1e6:.1f} MPa / "
         f"{fine['safety_factor']:.2f} |",
         f"| minimum detectable torque (1σ noise of the paper's chain) | {fine['min_detectable_torque_Nm'] * 1e3:.0f} mN·m |",
         f"| minimum detectable torque (ENOB 16 resolution, full bridge) | "
         f"{fine['min_detectable_torque_enob_Nm'] * 1e3:.0f} mN·m |",
         "| single-arm leak of Mx / My (% of rated output per N·m) | "
         f"{fine['crosstalk_single_arm_percent']['Mx_per_Nm']:.0f} / "
         f"{fine['crosstalk_single_arm_percent']['My_per_Nm']:.0f} |", "",
         _stiffness_paragraph(),
         "The single-arm leak is what one gauge alone sees of an off-axis moment: the bridge cancels "
         "it only as well as its arms match. Arms mismatched by 1 % (a typical gauge-factor "
         "tolerance) leak about 1 % of it, i.e. "
         f"≈ {fine['crosstalk_single_arm_percent']['My_per_Nm'] / 100:.2f} % of rated output per N·m of "
         "bending moment: on a leg, where the joint carries bending moments of the order of the torque, "
         "that, not the ideal-geometry cross-talk, is the number to budget.\n",
         "## Against the paper (§III-B)\n",
         "| statement | paper | ours |\n|---|---|---|",
         f"| strain at 0.4 N·m exceeds the ENOB ε_min | 1.53e-5 | {eps * 0.4:.3g} (yes) |",
         f"| strain at 0.001 N·m reaches the ideal ε_min | 5.96e-8 | {eps * 1e-3:.3g} |",
         f"| max differential output ≈ 10 mV | ≈ 10 mV | {fine['output_mV_at_rated']:.2f} mV at {T:g} N·m "
         "(bridge output, before any gain) |", "",
         "The paper's two statements about its disc disagree by an order of magnitude: eq. 11 and "
         "its FEA sentence put the strain near 4–6e-5 per N·m (ε_min reached at 0.4 N·m, resp. "
         "0.001 N·m), which this design meets; the ~10 mV maximum output over a 0–2 N·m range would "
         "need ≈ 5.7e-4 per N·m at 5 V, ten times more, which the `bridge` package's default "
         "assumes (README). For a spoke flexure the peak stress per unit gauge strain is "
         "set by the spoke's proportions (≈ 4 G L/w for a guided beam, more at the fillets), not its size: ours runs "
         f"{fine['max_von_mises_Pa'] / (eps * T) / 1e9:.0f} GPa per unit strain, so a disc of this "
         f"layout reading 5.7e-4 per N·m would see ≈ {fine['max_von_mises_Pa'] / eps * PAPER_STRAIN_PER_NM / 1e6:.0f} "
         f"MPa at {T:g} N·m, against σ_y = {fine['material']['yield_Pa'] / 1e6:.0f} MPa. We think the "
         "10 mV is after amplification or at a larger load, but the paper does not say. Both "
         "readings are kept and labelled.\n",
         "## Beam-theory check (`designs/beam_check.toml`: thin spokes, rim clamped)\n",
         "Guided beams clamped in a rigid hub (a = 4 mm) and rim (b = 18 mm), w = 2 mm, t = 1 mm: "
         f"k_beam = {k_beam:.0f} N·m/rad, ε₄₅ = 1.5 V/(wt)/(2G) averaged over the grid = "
         f"{eps_beam * 1e6:.2f} µε per N·m.\n",
         "| mesh | DOFs | ε_FEM / ε_beam | k_FEM / k_beam |\n|---|---|---|---|",
         *[f"| P2 {s} | {n:,} | {e:.4f} | {k:.3f} |" for s, n, e, k in beam_rows], "",
         "The strain sits 1–2 % above beam theory, where Saint-Venant's surface shear on a t/w = ½ "
         "section (≈ +3 %) puts it; the stiffness is below the beam's, as it must be (plane sections "
         "and rigid clamps make the beam kinematically stiffer; the spoke roots are compliant; "
         "`flexure.beam`). "
         "`tests/test_flexure_design.py` asserts both.\n",
         "## Sweep: spoke width × thickness (P2 coarse)\n",
         sweep_table(rows, keys), "",
         "Sensitivity ∝ 1/(w t) (shear on the spoke's centre line), stiffness ∝ t w³, stress ∝ "
         "1/(t w²): thin spokes buy sensitivity with stiffness and safety factor.\n",
         "![trade-off](flexure_sweep.png)\n",
         "![strain field](flexure_strain.png)\n", "![von Mises](flexure_von_mises.png)\n",
         "Fields at rated torque as VTU for ParaView: `torquebench flexure --vtu disc.vtu`.\n"]
    md = write_text_atomic(out_dir / "flexure.md", "\n".join(L))
    return [md, strain_png, vm_png, sweep_png]
