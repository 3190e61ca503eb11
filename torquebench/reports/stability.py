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
     "observer stays numerically sound (issue 14 adds chunked 10 M logs: re-point this row)", "see test",
     "tests/test_observer.py::test_long_log_is_numerically_sound"),
    ("Logs with gaps", "skipped rows (NaN) in a log",
     "the gap step is taken exactly with its own Δt (issue 16 adds time-stamp plausibility: re-point)",
     "see test", "tests/test_observer.py::test_gap_from_skipped_rows_is_taken_exactly"),
    ("Near-incompressible material", "ν → 0.5",
     "design flagged, not printed (issue 13 owns ν = 0.45/0.49/0.499 and P1 locking: re-point)", "see test",
     "tests/test_flexure_design.py::test_near_incompressible_design_is_flagged_not_printed"),
    ("Mesh quality / thin features", "paper disc mesh",
     "quality report, refinement at the gauges (issue 13 adds sliver refusal thresholds: re-point)", "see test",
     "tests/test_flexure_design.py::test_mesh_quality_report_and_refinement_at_the_gauges"),
    ("Singular postures", "straight and folded knee",
     "unobservable part NaN with a reason", "see test", "tests/test_sim_extreme.py::test_knee_straight_and_folded"),
    ("Force along the link", "F parallel to the link",
     "flagged parallel_to_link, never a large wrong α", "see test",
     "tests/test_localization.py::test_exactly_parallel_and_tiny_forces_are_flagged"),
    ("Tiny and huge forces", "poke forces over decades",
     "localized or flagged small_force", "see test", "tests/test_sim_extreme.py::test_tiny_and_huge_forces"),
    ("Forces at the noise floor", "|F| below 5σ of the contact-free rows",
     "detection declines (small_force) rather than localizing noise (issue 14 reworks: re-point)", "see test",
     "tests/test_observer.py::test_noise_thresholds_use_only_contact_free_samples"),
    ("Saturated ADC samples", "readings beyond full scale",
     "clipped to the rails by the ADC model (issue 11 flags saturated counts: re-point)", "see test",
     "tests/test_bridge.py::test_quantize_and_saturate"),
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
    from torquebench.errors import InputError
    from torquebench.io import REPO_ROOT
    from userio.files import write_text_atomic

    bad = missing_tests(REPO_ROOT)
    if bad:
        raise InputError(f"reports/stability: rows name tests that do not exist: {', '.join(bad)}")
    lines = ["# Stability: stiff and extreme cases", "",
             f"Generated {_dt.datetime.now(_dt.timezone.utc):%Y-%m-%d}. Each row names the test that checks it "
             "(all pass: `python -m pytest -q` + the test id). Numbers are from the test or measured when the "
             "row was written, on a loaded 2-core machine.", "",
             "| case | input | what the component does | number | test |", "|---|---|---|---|---|"]
    for case, inp, does, number, test in ROWS:
        lines.append(f"| {case} | {inp} | {does} | {number} | `{test}` |")
    path = Path(out_dir) / "stability.md"
    write_text_atomic(path, "\n".join(lines) + "\n")
    return [path]
