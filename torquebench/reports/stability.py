"""reports/stability.md: one row per stiff or extreme case, what each component does, the number it
gives and the test that checks it (``tests/test_file.py::test_name``, verified to exist at build).

The numbers are those measured when the row was written (see the test for the live assertion);
the builder refuses to write a row whose test does not exist.
"""

from __future__ import annotations

import ast
import datetime as _dt
from pathlib import Path

# (case, input, what the component does, number, test)
ROWS = [
    ("Stiff servo, explicit integrator", "moving_leg, kp = 1e12, RK45",
     "simulator refuses up front: explicit steps ≥ |λ_max|·T/3.3, names the stiffness ratio and suggests Radau/BDF",
     "fastest pole 5.44e7 1/s, stiffness ratio 692; refused in < 1 s",
     "tests/test_stability.py::test_stiff_servo_explicit_integrator_refused_up_front_with_stiffness_ratio"),
    ("Stiff servo, implicit integrator", "moving_leg, kp = 1e12, BDF (ran > 2 min silently before)",
     "cost probe extrapolates the run time, or the watchdog (tqdm bar on stderr after 2 s) stops it after 5 s; "
     "one line naming the limit; raisable with `simulate --max-run-time S`",
     "predicted 16–250 s for 0.5 s simulated vs limit 10 s; stopped within ~5 s",
     "tests/test_stability.py::test_stiff_servo_kp_1e12_implicit_is_stopped_at_the_run_time_limit"),
    ("Huge duration", "`simulate --duration 1e9`",
     "refused before integrating: 1e12 log samples > 2e7 held in memory; exit 2, one line, nothing written",
     "1e12 samples", "tests/test_stability.py::test_huge_duration_refused_before_integrating"),
    ("Stiff base mount", "k = 5e5, 5e6, 5e7 N/m (fixed base)",
     "BDF stays accurate against Radau rtol 1e-11; fixed-step RK4 refused when |R(hλ)| > 1, naming the fastest pole; "
     "stiffness ratio in the stats",
     "BDF max |q − q_ref| < 1e-6", "tests/test_stability.py::test_stiff_mount_implicit_accurate_rk4_refused_with_pole_reported"),
    ("Mount stiffness ×1000", "floating base, Table II springs ×1000",
     "runs (stiff-capable BDF) and the contact is still localized", "see test",
     "tests/test_sim_extreme.py::test_base_stiffness_times_1000_runs_and_is_localized"),
    ("RK4 step too large", "RK4 with h above 2.78/|λ_max|",
     "refused with |R(hλ)| and the largest stable h; converges at order 4 when small", "|R| > 1 refused",
     "tests/test_sim.py::test_rk4_refused_when_step_too_large_and_converges_when_small"),
    ("ZOH controller too slow", "zero-order-hold PD at 1 kHz",
     "refused: discrete closed-loop spectral radius ≥ 1 and the minimum stable rate",
     "ρ ≥ 1", "tests/test_sim.py::test_zoh_at_1kHz_is_refused_with_a_clear_message"),
    ("Integration error estimate", "RK45 rtol 1e-4; RK4 h = 5e-5",
     "`q_rad_error_estimate` from a 10× tighter (h/2, Richardson) rerun of the first window",
     "within ×10 (RK45) / ×3 (RK4) of the true error vs Radau 1e-11",
     "tests/test_stability.py::test_integration_error_estimate_brackets_the_true_error"),
    ("Observer gain × step", "K·Δt = 0.1, 1, 10, 100",
     "exact discretization a = e^{−KΔt} ∈ (0, 1) always stable, no overshoot; naive Euler a = 1 − KΔt "
     "diverges (|a| > 1) for KΔt > 2 and is refused",
     "naive |a| = 9 at KΔt = 10, 99 at 100", "tests/test_stability.py::test_observer_gain_times_step_stays_stable_and_naive_euler_would_not"),
    ("Observer at KΔt = 10 on a real log", "moving scene, K = 10/Δt",
     "exact form finite and within 2e-3 of the step-mean τ_ext; explicit refused at KΔt ≥ 2",
     "|r − τ̄_ext| < 2e-3", "tests/test_observer.py::test_exact_discretization_stable_at_K_dt_10_and_explicit_refused"),
    ("Long logs", "1e6-sample log",
     "observer stays numerically sound", "see test",
     "tests/test_observer.py::test_long_log_is_numerically_sound"),
    ("Long logs, bounded memory", "10 M-sample CSV log (`estimate --out`)",
     "read, estimated and written in chunks of 65 536 with the observer, detector and open contact "
     "carried across boundaries",
     "peak RSS 437 MB (2 M samples: 421–442 MB; before: 5.5 GB for 10 M); traced peak 0.99× for a 4× longer log",
     "tests/test_chunked.py::test_memory_does_not_grow_with_the_log"),
    ("Chunk boundaries", "7- and 333-sample chunks, pokes and the noise-floor head straddling them",
     "the stream gives the one-shot per-sample numbers (chi-square, CUSUM, paper isolation, debounce, "
     "expected contacts, sensor timing, quiet windows)", "bit-equal for 10 detector configurations",
     "tests/test_chunked.py::test_chunks_of_any_size_give_the_one_shot_numbers"),
    ("CUSUM on an extreme statistic", "100 N contact (s ≈ 1e12) with a NaN sample",
     "the CUSUM clips its steps at the cap in whole-number arithmetic",
     "no overflow; alarm from sample 0; released 9 samples after s = 0",
     "tests/test_sequential.py::test_cusum_on_an_extreme_statistic_saturates_without_overflow"),
    ("Sensor timing declared wrongly", "`mean` declared on instantaneous simulated readings",
     "the residual swells (the simulator now writes its declaration beside every log)",
     "max ‖r‖ 0.259 against 0.0019 declared correctly (0.000475 at 2 kHz: second order in Δt)",
     "tests/test_sim_timing.py::test_estimate_reads_it_and_the_residual_stays_at_discretization_level"),
    ("Scene with noise-free sensors", "scene whose sensors have zero σ, default (chi-square) detector",
     "refused in one line asking for `[estimator] threshold` (a zero-σ residual cannot be whitened)",
     "exit 2", "tests/test_scene_noise.py::test_zero_noise_scene_needs_a_threshold"),
    ("Counts read with a calibration in mV", "scene: ADC-count columns, stored calibration fitted in mV",
     "refused before any work", "exit 2, names calibration.file and source.reading_unit",
     "tests/test_pipeline.py::test_stored_calibration_reading_unit_must_match_the_counts_columns"),
    ("Logs with gaps", "skipped rows (NaN) in a log",
     "the gap step is taken exactly with its own Δt; backwards, duplicate or irregular stamps are refused",
     "see test", "tests/test_observer.py::test_gap_from_skipped_rows_is_taken_exactly"),
    ("Near-incompressible material, ν = 0.45 / 0.49 / 0.499",
     "Lamé thick cylinder in plane strain (exact answer), P1 and P2 on the same meshes",
     "P2 stays within its own two-level Richardson/GCI error estimate at every ν; P1 locks: its error grows "
     "with ν and its convergence stalls; the solver flags `near_incompressible` from ν = 0.49 for P1, "
     "from 0.49999 for P2",
     "bore hoop-strain error, mesh k = 4: P2 (5,049 DOFs) 9.2e-5 / 1.9e-4 / 3.6e-4; P1 (918 DOFs) "
     "2.3 % / 7.3 % / 19.7 %, P1 order 1.7 at ν = 0.45 → 0.37 at 0.499",
     "tests/test_stability_extreme.py::test_near_incompressible_p2_stays_within_its_error_estimate_while_p1_locks"),
    ("Near-incompressible design, P1", "a flexure design with ν = 0.499, linear tetrahedra",
     "figures withheld: NaN with the reason `near_incompressible` (P1 flagged from ν = 0.49, where it locks)",
     "NaN", "tests/test_flexure_design.py::test_near_incompressible_design_is_flagged_not_printed"),
    ("Near-incompressible material, P2", "Lamé cylinder, quadratic tetrahedra, ν = 0.49 / 0.499 / 0.4999",
     "answers printed, not flagged: P2 does not lock (the condition estimate grows ×10 per decade of 1 − 2ν)",
     "bore strain error 1.9e-4 / 3.6e-4 / 4.5e-4",
     "tests/test_fem_incompressible.py::test_p2_is_accurate_and_not_flagged_up_to_0p4999"),
    ("Nearly incompressible beyond the measured range, P2", "Lamé cylinder, P2, ν = 0.49999",
     "flagged `near_incompressible`: accuracy is not shown beyond this point (4.8e-4 measured there)",
     "NaN", "tests/test_fem_incompressible.py::test_p2_converges_at_0p4999_and_is_flagged_at_0p49999"),
    ("Scene quiet window holding a contact", "`[estimator] quiet_window_s` over the poke",
     "refused: the residual changes within the stretch", "exit 2, names estimator.quiet_window_s",
     "tests/test_scene_noise.py::test_quiet_window_states_the_noise_and_a_window_with_the_poke_is_refused"),
    ("`--rtol` past what can be meshed", "a finer level refused by the mesh-cost check",
     "refinement stops; the levels solved are the answer, a warning names the refusal",
     "exit 0, warning", "tests/test_flexure_cli.py::test_rtol_stopped_by_a_refused_finer_level_keeps_the_levels_solved"),
    ("Log whose sensors are noisier than the default", "examples/sim logs (bridge σ_τ 0.0133 N·m) "
     "estimated with and without their LOG.noise.toml",
     "declared: the residual whitened by the sensors' own noise; undeclared: the paper leg's default "
     "(0.005 N·m) is assumed and said", "contact-free flagged 0.00 % / 0.67 % declared, 6.6 % / 7.9 % not",
     "tests/test_examples.py::test_declared_noise_keeps_contact_free_samples_quiet"),
    ("Bad noise declaration", "LOG.noise.toml with a zero σ, two FT values, a misspelt key, a missing "
     "or wrong-length torque σ", "refused before any work", "exit 2, names the file and field",
     "tests/test_estimate_cli.py::test_noise_side_file_is_read_and_options_override_it"),
    ("Footprint off flat faces", "a gauge grid not lying on flat mesh faces",
     "the gauge read-out falls back to the 6×3 Gauss rule over the grid", "see test",
     "tests/test_flexure_gauge_footprint.py::test_grid_off_flat_faces_falls_back_to_the_gauss_rule"),
    ("CSV fields pyarrow would read differently", "`NAN`, `nan(1)` and similar spellings in a log",
     "the block is handed to pandas, which names the line and column", "exit 2 (line 2702, column q1)",
     "tests/test_log_reader.py::test_fields_pandas_refuses_name_their_line_on_the_fast_path"),
    ("Decimal strings at halfway points between doubles", "log values exercising the last bit",
     "both parsers round correctly", "bit-equal to Python's float()",
     "tests/test_log_reader.py::test_last_bit_values_equal_through_both_parsers_and_python_float"),
    ("Incompressible or impossible material", "ν = 0.5 in a design file",
     "refused: exit 2 naming `material.nu` (must lie in (−1, 0.5))", "exit 2",
     "tests/test_flexure_design.py::test_bad_design_names_file_and_field"),
    ("Mesh quality / thin features", "paper disc mesh",
     "quality report (min dihedral, radius ratio, slivers), refinement at the gauges", "see test",
     "tests/test_flexure_design.py::test_mesh_quality_report_and_refinement_at_the_gauges"),
    ("Singular postures", "straight and folded knee",
     "unobservable part NaN with a reason", "see test", "tests/test_sim_extreme.py::test_knee_straight_and_folded"),
    ("Force along the link", "F parallel to the link",
     "flagged parallel_to_link, never a large wrong α", "see test",
     "tests/test_localization.py::test_exactly_parallel_and_tiny_forces_are_flagged"),
    ("Force along link 2 with FT noise", "a poke along the shank, Table II FT noise",
     "ambiguity tolerance from the residual noise: refused as ambiguous", "100 % of draws flagged",
     "tests/test_uncertainty.py::test_force_along_the_link_is_flagged_not_guessed"),
    ("Tiny and huge forces", "poke forces over decades",
     "localized or flagged small_force", "see test", "tests/test_sim_extreme.py::test_tiny_and_huge_forces"),
    ("Forces at the noise floor", "|F| below 5σ of the contact-free rows",
     "detection declines (small_force) rather than localizing noise", "see test",
     "tests/test_observer.py::test_noise_thresholds_use_only_contact_free_samples"),
    ("Saturated ADC samples (model)", "readings beyond full scale",
     "clipped to the rails by the ADC model", "see test",
     "tests/test_bridge.py::test_quantize_and_saturate"),
    ("Saturated ADC samples (pipeline)", "raw counts at the 24-bit rails in the calibrated-sensor loop",
     "flagged, NaN, kept out of detection; never silently clipped", "2 of 3 rail samples flagged",
     "tests/test_pipeline.py::test_calibrated_torques_flag_saturated_counts_and_keep_them_out"),
    ("Saturated ADC samples (apply)", "a full-scale 24-bit count in `apply`",
     "flag `saturated_adc`, torque NaN", "null (was 1.5e6 N·m)",
     "tests/test_hostile.py::test_apply_flags_saturated_adc_counts"),
    ("Reading outside the calibrated range", "`apply` on a reading of 1e300",
     "flag `outside_calibrated_range`, NaN; never extrapolated", "null (was 1.8e299 N·m)",
     "tests/test_hostile.py::test_apply_flags_instead_of_extrapolating"),
    ("Constant or saturated calibration readings", "every reading 8388607",
     "refused before the fit (emcee would raise)", "exit 2",
     "tests/test_hostile.py::test_constant_or_saturated_calibration_readings_exit_2"),
    ("Integrator tolerance too loose", "scene `rtol = 1.0`",
     "refused (rtol must lie in [1e-13, 1e-2])", "exit 2",
     "tests/test_hostile.py::test_scene_tolerances_outside_sensible_range_exit_2"),
    ("Time in milliseconds", "a log whose t column is in ms",
     "refused, the unit mix-up named (velocity scale 1e-3)", "exit 2",
     "tests/test_plausibility.py::test_time_in_milliseconds_is_refused"),
    ("Angles in degrees", "a log whose angles are in degrees",
     "refused (|q| > 2π, velocity scale 57.3)", "exit 2",
     "tests/test_plausibility.py::test_angles_in_degrees_are_refused"),
    ("Implausible sampling period", "steps of 1e-12 s or 3600 s",
     "refused (period must lie in 10 µs–1 s)", "exit 2",
     "tests/test_plausibility.py::test_implausible_sampling_period_is_refused"),
    ("Interval-mean sensor timing", "forces averaged over each sample during a 10 Hz base bounce",
     "declared `mean`: the matching step quadrature; undeclared: a false residual", "‖r‖ 8.7e-6 (0.68 undeclared)",
     "tests/test_timing.py::test_mean_sampled_forces_with_fast_bounce_need_the_mean_declaration"),
    ("Converter group delay", "1.3 ms filter delay on the force channels",
     "declared `delay:`: readings realigned", "‖r‖ 0.022 (1.78 undeclared)",
     "tests/test_timing.py::test_group_delay_declaration_realigns"),
    ("Contact-free fast motion with sensor noise", "10 Hz base motion, FT σ 0.1 N, τ σ 0.005 N·m",
     "chi-square detector at a stated false-alarm rate", "0 % flagged (paper ε: 2.8 %)",
     "tests/test_detection_done_when.py::test_contact_free_fast_motion_flags_under_0p1_percent"),
    ("Quiet window that holds a contact", "`estimate --quiet-window` over a poke",
     "refused (first and last quarters differ by > 6 standard errors)", "exit 2",
     "tests/test_noise_detection.py::test_quiet_window_refuses_a_contact"),
    ("Propagation too large", "`propagate --grid 100000` or `--draws 100000000`",
     "refused before any work with the size (postures × draws × 2 methods), limit `--max-localizations`",
     "1e13 / 2e10 localizations; exit 2",
     "tests/test_hostile.py::test_propagate_runaway_size_refused_before_any_work"),
    ("Absurd flexure thickness", "a disc 1e-6 mm or 1e4 mm thick",
     "refused before meshing with the estimated element count (`--max-elements`)", "~1.7e15 / ~1.6e6 tets; exit 2",
     "tests/test_flexure_cli.py::test_absurd_thickness_refused_before_meshing_with_the_cost"),
    ("Unreachable FEM tolerance", "`flexure --rtol` below what the DOF cap allows",
     "stops at `--max-dofs` and warns", "warning",
     "tests/test_flexure_cli.py::test_rtol_stopped_by_the_dof_cap_says_so"),
    ("Thick disc, small gauges", "5 mm, no fillets, 0.5 mm gauges",
     "gmsh graded mesh: no slivers, arms balanced", "min dihedral 8.8°, arms within 2 %",
     "tests/test_fem_thick_disc.py::test_thick_disc_default_mesh_has_no_slivers_and_balanced_arms"),
    ("Quarter bridge near its singularity", "output ratio v → 1/2 (R1 → ∞) and beyond",
     "finite and exact up to 1/2 − 1e-6; at and past the pole NaN with a BridgeInverseWarning, never a huge number", "see test", "tests/test_bridge.py::test_quarter_inverse_near_singularity"),
    ("Unconverged MCMC", "chain shorter than 50 τ",
     "fit flagged `converged = false` and refused by the store (as emcee's AutocorrError)", "see test",
     "tests/test_calibration.py::test_unconverged_fit_is_flagged_and_refused"),
    ("Non-identifiable calibration model", "too few distinct loads for the model",
     "InputError naming the model", "see test", "tests/test_calibration.py::test_model_identifiability_errors"),
    ("Out-of-range reading (quadratic inverse)", "reading beyond the calibrated range",
     "flagged out of range, exact inverse inside", "see test",
     "tests/test_store.py::test_quadratic_inverse_is_exact_and_flags_out_of_range"),
    ("Tiny and huge sensors: chain", "1e-3 N·m and 1e4 N·m full scale (strain per N·m 1 and 1e-7, 1e-3 rated strain)",
     "the bridge/ADC chain works in strain: same ADC codes, noise and read-back relative to full scale as "
     "the 2 N·m sensor (no absolute epsilon)",
     "codes equal (≤ 1 count at rounding ties); relative noise and counts per full scale equal to 1e-12",
     "tests/test_stability_extreme.py::test_tiny_and_huge_sensor_chain_is_exact_relative_to_its_scale"),
    ("Tiny and huge sensors: calibration", "dead weights 0.005–0.5 g (1e-3 N·m) and 5–5000 kg (1e4 N·m) at 0.205 m",
     "emcee fit converges; slope recovered; its σ relative to the slope is the 2 N·m sensor's",
     "slope within 4σ; relative σ equal within 5 %",
     "tests/test_stability_extreme.py::test_tiny_and_huge_sensor_calibration_fit_is_correct_relative_to_its_scale"),
    ("float32 sensor log", "examples/leg_poke as Parquet float32 columns and as CSV with 7 significant digits",
     "read and estimated as usual", "episode α, F, p move ≤ 3e-5 of their own 1σ error estimate",
     "tests/test_stability_extreme.py::test_float32_sensor_log_changes_the_estimate_by_far_less_than_its_error_estimate"),
    ("float32 calibration CSV", "the shipped session, readings rounded to float32 and written with 7 digits",
     "fit as usual", "exact posterior moves 1e-5 σ, emcee mean (same seed) 4e-3 σ",
     "tests/test_stability_extreme.py::test_float32_calibration_csv_changes_the_fit_by_far_less_than_its_error_estimate"),
    ("Correlated ADC noise in `acquire`", "AR(1) noise, τ = 19 samples, 4000-sample windows",
     "standard errors of the mean reading, its noise and the settling step use n_eff = n/τ (τ from the "
     "window; a window shorter than 100 τ is flagged as underestimating)",
     "z-score spread 1.0 over 300 windows (σ/√n would be 4.4× too small)",
     "tests/test_acquire_error_estimates.py::test_reading_and_noise_standard_errors_are_honest"),
    ("Settling test on correlated noise", "AR(1) noise, τ = 19 samples; the same plus a 3σ drift",
     "limit 4 SE of the half-window step with τ of the detrended window: correlated noise passes, a drift "
     "does not (its slow part is not read as correlation)",
     "100 % settled (former white-noise limit: 64 %); the drift refused",
     "tests/test_acquire_error_estimates.py::test_settle_test_accepts_correlated_noise_and_still_catches_a_drift"),
    ("Monte Carlo percentile", "propagate at 400 draws",
     "reports the percentile's MC standard error; it matches the scatter over 60 seeds within ±35 %",
     "see test", "tests/test_uncertainty.py::test_percentile_and_rms_standard_errors_match_the_spread_over_seeds"),
]


def missing_tests(root: Path) -> list[str]:
    """Rows whose ``file::name`` does not name a test function in that file."""
    missing = []
    for *_, test in ROWS:
        file, name = test.split("::")
        path = root / file
        names = set()
        if path.exists():
            names = {n.name for n in ast.walk(ast.parse(path.read_text())) if isinstance(n, ast.FunctionDef)}
        if name not in names:
            missing.append(test)
    return missing


def build(out_dir: Path) -> list[Path]:
    from userio.errors import InputError
    from torquebench.io import REPO_ROOT
    from userio.files import write_text_atomic

    bad = missing_tests(REPO_ROOT)
    if bad:
        raise InputError(f"reports/stability: rows name tests that do not exist: {', '.join(bad)}")
    lines = ["# Stability: stiff and extreme cases", "",
             f"Generated {_dt.datetime.now(_dt.timezone.utc):%Y-%m-%d}. Each row names the test that checks it "
             "(all pass: `python -m pytest -q` + the test id). Numbers are from the test or measured when the "
             "row was written, on a loaded 2-core machine.", "",
             f"**Headline:** {len(ROWS)} stiff and extreme inputs (stiff servos and mounts, huge durations, "
             "degenerate meshes and logs), each refused up front with one line or handled accurately, each "
             "checked by the test named in its row", "",
             "| case | input | what the component does | number | test |", "|---|---|---|---|---|"]
    for case, inp, does, number, test in ROWS:
        lines.append(f"| {case} | {inp} | {does} | {number} | `{test}` |")
    path = Path(out_dir) / "stability.md"
    write_text_atomic(path, "\n".join(lines) + "\n")
    return [path]
