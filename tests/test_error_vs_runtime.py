"""The error-vs-run-time report: Pareto front, cheapest-setting table, section discovery."""

import importlib
import pkgutil

import numpy as np
import pytest

import torquebench.reports as reports
from torquebench.reports import error_vs_runtime as evr


def test_pareto_front_and_cheapest_setting():
    t = [1.0, 2.0, 3.0, 0.5, 4.0]
    e = [0.1, 0.2, 0.01, 0.5, 0.001]          # (2.0, 0.2) is dominated by (1.0, 0.1)
    assert evr.pareto_front(t, e).tolist() == [3, 0, 2, 4]
    rows = [{"setting": str(i), "time_s": ti, "error": ei} for i, (ti, ei) in enumerate(zip(t, e))]
    assert evr.cheapest(rows, 0.1)["setting"] == "0"
    assert evr.cheapest(rows, 0.01)["setting"] == "2"
    assert evr.cheapest(rows, 1e-4) is None


def test_section_markdown_lists_targets_and_marks_the_front(tmp_path):
    rows = [{"setting": "a", "family": "x", "time_s": 1.0, "error": 0.05, "k": 1.0},
            {"setting": "b", "family": "x", "time_s": 2.0, "error": 0.2, "k": 2.0},
            {"setting": "c", "family": "y", "time_s": 3.0, "error": 0.005, "k": 3.0}]
    lines, pngs = evr.section("Demo family", rows, tmp_path, "demo", error_label="err", reference="exact")
    text = "\n".join(lines)
    assert lines[0] == "## Demo family" and pngs[0].stat().st_size > 1000
    assert "| 10.0% | a |" in text and "| 1.0% | c |" in text and "| 0.1% | none reached" in text
    assert "| a ★ |" in text and "| b |" in text


def test_every_report_module_with_a_section_is_discovered():
    expected = set()
    for info in pkgutil.iter_modules(reports.__path__):
        if info.name in ("error_vs_runtime", "stability") or info.name.startswith("_"):
            continue
        if hasattr(importlib.import_module(f"torquebench.reports.{info.name}"), "error_vs_runtime_section"):
            expected.add(f"torquebench.reports.{info.name}")
    assert {fn.__module__ for fn in evr.discovered_sections()} == expected


def test_propagation_section_error_shrinks_with_draws_and_reported_se_is_honest(tmp_path):
    rows, info = evr.propagation_rows(quick=True)
    mc = [r for r in rows if r["family"] == "Monte Carlo"]
    assert mc[-1]["p95_error"] < mc[0]["p95_error"]
    # the reported standard error is the right size: the actual error at 3000 draws is within 3 SE
    assert mc[-1]["p95_error"] < 3 * mc[-1]["reported_p95_se_rel"] + info["ref_se"]


def test_calibration_rows_converge_toward_the_exact_posterior():
    rows, _ = evr.calibration_rows(quick=True)
    rule = [r for r in rows if r["family"] == "autocorrelation stopping rule"][0]
    assert rule["error"] < 0.05                   # ≥ 50 τ: mean within 5 % σ, σ within 5 %


def test_observer_rows_trade_delay_against_noise():
    rows, _ = evr.observer_rows(quick=True)
    at_1k = {r["setting"]: r for r in rows if r["family"] == "1000 Hz"}
    slow, fast = at_1k["K = 30 1/s @ 1000 Hz"], at_1k["K = 300 1/s @ 1000 Hz"]
    assert fast["rise_90pct_s"] < 0.2 * slow["rise_90pct_s"]
    assert abs(slow["rise_90pct_s"] - np.log(10) / 30) < 0.01     # first-order lag: t90 = ln 10 / K
    assert fast["noise_rel"] > slow["noise_rel"]


def test_observer_detection_delay_is_below_one_sample_far_above_threshold_and_ln2_over_K_near_it():
    """7 N is far above the threshold: detected on the first sample holding it (< Δt, not "0").
    At twice the threshold the noise-free statistic crosses half its final value at ln 2 / K
    (first-order lag); with noise, no later."""
    rows, _ = evr.observer_rows(quick=True)
    for r in rows:
        assert "first sample" in r["delay_7N"]
    for r in rows:
        dt = 1.0 / float(r["family"].split()[0])
        # noise-free: the lag's crossing of half its final value, to within one sample
        assert abs(r["delay_2x_noise_free_s"] - r["ln2_over_K_s"]) <= dt + 1e-9, r["setting"]
        # with noise the statistic only gets an extra push: never later than one sample after that
        assert r["delay_2x_threshold_s"] <= r["delay_2x_noise_free_s"] + dt + 1e-9, r["setting"]
        assert 0.0 < r["force_2x_threshold_N"] < 0.5


def test_localizer_rows_dynamic_beats_paper_on_the_moving_leg():
    rows, _ = evr.localizer_rows(quick=True)
    by = {r["family"]: r["error"] for r in rows}
    assert by["dynamic (moving)"] < 0.2 * by["paper (moving)"]


def test_fem_extrapolation_recovers_the_limit_and_the_order_and_bounds_oscillation():
    from torquebench.reports.fem import extrapolate

    n = np.array([1.2e4, 3.5e4, 9.8e4])
    h = (n / n[-1]) ** (-1 / 3)
    for p in (0.9, 2.0, 3.0):
        ex = extrapolate(n, 5.0 + 0.3 * h ** p)
        assert ex["value"] == pytest.approx(5.0, rel=1e-9) and ex["order"] == pytest.approx(p, rel=1e-6)
        assert ex["uncertainty"] == pytest.approx(0.3, rel=1e-6)        # the whole correction
    fast = extrapolate(n, [5.2, 5.01, 5.009])              # change ratio 190: order clipped at 4
    assert fast["value"] == 5.009 and fast["uncertainty"] == pytest.approx(1.25 * 0.19)
    osc = extrapolate(n, [5.1, 4.9, 5.0])
    assert np.isnan(osc["order"]) and osc["value"] == 5.0 and osc["uncertainty"] == pytest.approx(0.25)


@pytest.mark.slow
def test_fem_section_quick_has_the_contract_and_p1_error_falls_with_refinement(tmp_path):
    from torquebench.reports.fem import error_vs_runtime_section

    lines, pngs = error_vs_runtime_section(tmp_path, quick=True)
    text = "\n".join(lines)
    assert lines[0].startswith("## Flexure FEM")
    assert len(pngs) == 2 and all(p.stat().st_size > 1000 for p in pngs)
    for fig in ("gauge strain per N·m", "torsional stiffness"):
        assert f"### Flexure FEM, paper disc: {fig}" in text
    assert "Cheapest setting for a target" in text and "QUICK mode" in text
    rows = [ln for ln in lines if ln.startswith("| P1, h × ")]
    assert len(rows) == 6
    values = [float(ln.split("|")[-2]) for ln in rows[:3]]              # gauge strain, coarse → fine
    assert values == sorted(values)                                     # P1 too stiff, rising to the limit
    # the second mesher is a setting of ours; scikit-fem is an outside point, listed apart, never starred
    assert sum(ln.startswith("| P1 tetgen, h × 4") for ln in lines) == 2
    outside = [ln for ln in lines if ln.startswith("| scikit-fem P2 (same mesh), h × 4 |")]
    assert len(outside) == 2 and not any("★" in ln for ln in outside)
    all_settings = text.split("All settings")[1].split("Outside point")[0]
    assert "scikit-fem" not in all_settings
    # P2 on the coarsest mesh reads more strain than P1 on the finest (P1 is too stiff)
    sk_strain = float(outside[0].split("|")[5])
    assert sk_strain > max(values)


def test_splicing_the_fem_section_leaves_the_other_sections_alone(tmp_path):
    from benchmark_module import benchmark_module

    bench = benchmark_module("bench_accuracy")
    md = tmp_path / "error_vs_runtime.md"
    md.write_text("# E\n\n## A\n\nkeep A\n_(section built in 1.0 s)_\n\n## Flexure FEM (old)\n\nstale\n"
                  "_(section built in 9.0 s)_\n\n## Z\n\nkeep Z\n")
    rows = [{"geometry": "paper disc", "mesher": m, "order": 2, "h_factor": f, "dofs": int(n), "time_s": t,
             "gauge_strain_per_Nm": 5.0 + 0.3 * (n / 4e4) ** (-2 / 3), "torsional_stiffness_Nm_per_rad": 1700.0 + n / 1e4}
            for m, f, n, t in (("gmsh", 2.0, 1e4, 10.0), ("gmsh", 1.0, 2e4, 20.0), ("gmsh", 0.5, 4e4, 40.0),
                               ("tetgen", 1.0, 3e4, 15.0), ("scikit-fem", 1.0, 2e4, 12.0))]
    bench.splice_fem_section(md, rows, 42.0, runs=2)
    text = md.read_text()
    assert text.startswith("# E\n\n## A\n\nkeep A\n_(section built in 1.0 s)_\n\n## Flexure FEM (P1 and P2")
    assert "stale" not in text and "9.0 s" not in text and text.endswith("_(section built in 42.0 s)_\n\n## Z\n\nkeep Z\n")
    assert "measured in 2 separate runs" in text and "| P2 tetgen, h × 1 ★ |" in text
    assert "| scikit-fem P2 (same mesh), h × 1 | 20,000 |" in text


def test_fem_section_lists_the_adaptive_default_with_its_own_estimate(tmp_path):
    """Adaptive rows (the default run at a --rtol) are a setting of ours: in the tables and on the
    front like the mesh levels, with their own relative ± beside their true error against the gmsh
    P2 reference (the adaptive rows never enter the reference)."""
    from torquebench.reports.fem import fem_section

    def fig(n):
        return {"gauge_strain_per_Nm": 5.0 + 0.3 * (n / 4e4) ** (-2 / 3), "torsional_stiffness_Nm_per_rad": 1700.0 + n / 1e4}

    rows = [{"geometry": "paper disc", "mesher": "gmsh", "order": 2, "h_factor": f, "dofs": int(n), "time_s": t, **fig(n)}
            for f, n, t in ((2.0, 1e4, 10.0), (1.0, 2e4, 20.0), (0.5, 4e4, 40.0))]
    rows.append({"geometry": "paper disc", "mesher": "adaptive", "order": 2, "h_factor": 0.02, "dofs": 30000,
                 "time_s": 5.0, "stopped_by": "rtol", "gauge_strain_per_Nm_estimate": 0.004,
                 "torsional_stiffness_Nm_per_rad_estimate": 0.011, **fig(3e4)})
    lines, pngs = fem_section(rows, tmp_path)
    text = "\n".join(lines)
    ad = [ln for ln in lines if ln.startswith("| P2 adaptive, --rtol 0.02")]
    assert len(ad) == 2 and all("★" in ln for ln in ad)              # fastest of the four: on both fronts
    assert any("0.004 (stopped by rtol)" in ln for ln in ad) and any("0.011 (stopped by rtol)" in ln for ln in ad)
    assert "--rtol = 0.02" in text and all(p.exists() for p in pngs)
    gm = [ln for ln in lines if ln.startswith("| P2, h × 2 ")]
    assert gm and all(ln.rstrip().endswith("| — |") for ln in gm)
