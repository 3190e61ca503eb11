"""`torquebench calibrate`: Bayesian (emcee) calibration of a static-loading session."""

from __future__ import annotations

import sys
from pathlib import Path

HELP = "fit calibration coefficients (emcee) to a loading-session CSV and store them safely"
EXAMPLES = """\
torquebench calibrate calibration/data/paper_link1_session.csv --out out/link1_cal.json
torquebench calibrate calibration/data/paper_link2_session.csv --out out/link2_cal.json --model hysteresis --json
"""


def add_arguments(parser) -> None:
    parser.add_argument("data", type=Path, help="static-loading session CSV: columns mass_g,reading[,direction,repeat,lever_arm_m,timestamp,sensor_id] (docs/conventions.md)")
    parser.add_argument("--out", type=Path, required=True, help="calibration JSON to write (its directory is created; an existing file is kept and NAME.vK.json written instead, unless --force)")
    parser.add_argument("--model", choices=("linear", "quadratic", "hysteresis"), default="linear",
                        help="reading model: linear (slope·m + offset), quadratic, or hysteresis (separate load/unload offsets) (default: %(default)s)")
    parser.add_argument("--force", action="store_true",
                        help="replace an existing --out (without it: keep it, write NAME.vK.json)")
    parser.add_argument("--lever-arm-m", type=float, default=None,
                        help="lever arm in m from the joint axis to the masses, if the CSV has no lever_arm_m column (default: the CSV's)")
    parser.add_argument("--mass-std-g", type=float, default=0.0,
                        help="standard uncertainty of the applied masses in g: errors-in-load term (default: %(default)s)")
    parser.add_argument("--sensor-id", default=None, help="sensor name (default: the CSV's sensor_id)")
    parser.add_argument("--seed", type=int, default=0, help="sampler seed, for reproducible fits (default: %(default)s)")
    parser.add_argument("--walkers", type=int, default=256,
                        help="emcee walkers, at least 8 (vectorized: many walkers cost little per step) (default: %(default)s)")
    parser.add_argument("--max-steps", type=int, default=50_000,
                        help="give up (and refuse to store) if not converged after this many steps (default: %(default)s)")
    parser.add_argument("--no-report", action="store_true",
                        help="skip the Markdown report and corner/residual plots beside --out")


# coefficient → its unit, for a reading in READING_UNIT and masses in g (calibration.fit's model
# reading = slope·m + offset + quad·m² + hysteresis·1{unloading} + ε, ε ~ N(0, sigma²))
_UNITS = {"slope": "{u}/g", "offset": "{u}", "quad": "{u}/g²", "hysteresis": "{u}", "sigma": "{u}"}
_KEYS = {"slope": "{u}_per_g", "offset": "{u}", "quad": "{u}_per_g2", "hysteresis": "{u}", "sigma": "{u}"}


def coefficient_unit(name: str, reading_unit: str) -> str:
    """Printed unit of a coefficient, e.g. slope → 'mV/g'."""
    return _UNITS.get(name, "{u}").format(u=reading_unit)


def coefficient_key(name: str, reading_unit: str) -> str:
    """Unit-suffixed JSON key of a coefficient, e.g. slope → 'slope_mV_per_g'."""
    return f"{name}_" + _KEYS.get(name, "{u}").format(u=reading_unit)


def report_paths(out: Path) -> tuple[Path, Path, Path]:
    """(Markdown report, corner PNG, residual PNG) written beside the calibration ``out``."""
    stem = out.with_suffix("")
    return (stem.with_name(stem.name + ".md"), stem.with_name(stem.name + "_corner.png"),
            stem.with_name(stem.name + "_residuals.png"))


def _report(doc: dict, fit, session, out: Path) -> list[tuple[Path, object]]:
    """The report files as ``[(path, writer)]`` for :func:`userio.files.write_files_atomic`."""
    from calibration.plots import corner_plot, residual_plot

    md, corner_png, resid_png = report_paths(out)
    post, ex, ch, dg = doc["posterior"], doc["exact"], doc["characterization"], doc["diagnostics"]
    unit = doc["reading_unit"]
    lines = [f"# Calibration {out.name} ({session.sensor_id})", "",
             f"Data: `{session.source}` (sha256 `{session.sha256[:16]}…`, {len(session)} readings). "
             f"Model: `{doc['equation']}` (reading in {unit}, mass in g).", "",
             "| coefficient | emcee mean | emcee std | 16 % | 84 % | exact mean | exact std |",
             "|---|---|---|---|---|---|---|"]
    for n in doc["coefficients"]:
        lines.append(f"| {n} | {post[n]['mean']:.6g} | {post[n]['std']:.3g} | {post[n]['p16']:.6g} | "
                     f"{post[n]['p84']:.6g} | {ex['mean'][n]:.6g} | {ex['std'][n]:.3g} |")
    lines += [f"| sigma | {post['sigma']['mean']:.4g} | {post['sigma']['std']:.3g} | "
              f"{post['sigma']['p16']:.4g} | {post['sigma']['p84']:.4g} | {ex['sigma_mean']:.4g} | |", "",
              f"R² (OLS) = {doc['ols']['r2']:.5f}; τ = {dg['tau_max']:.1f} steps; chain "
              f"{dg['n_steps']} steps × {dg['n_walkers']} walkers; acceptance "
              f"{dg['acceptance_fraction']:.2f}; burn-in {dg['burn_in']}; {dg['reason']}.", "",
              f"Non-linearity {ch['nonlinearity_pct_fs']:.3f} % FS, hysteresis "
              + (f"{ch['hysteresis_pct_fs']:.3f} % FS" if ch["hysteresis_pct_fs"] is not None else "n/a")
              + ", repeatability "
              + (f"{ch['repeatability_pct_fs']:.3f} % FS" if ch["repeatability_pct_fs"] is not None else "n/a")
              + f" (FS output {ch['fso']:.4g} {unit}).", "",
              f"![corner]({corner_png.name})", "", f"![residuals]({resid_png.name})", ""]
    return [(md, "\n".join(lines)),
            (corner_png, lambda tmp: corner_plot(fit, tmp, title=f"{session.sensor_id}: {fit.model}")),
            (resid_png, lambda tmp: residual_plot(session, fit, tmp))]


def _target(out: Path, force: bool, no_report: bool) -> Path:
    """The calibration path to write: ``out``, or its first free ``NAME.vK.json`` without --force
    (the report files of a versioned name must be free too; userio.outputs.free_version)."""
    from userio.outputs import free_version

    return out if force else free_version(out, (lambda c: ()) if no_report else report_paths)


def _plan(args, out: Path, replace: bool = False):
    """The output plan (userio.outputs): the calibration and its report files, never the data
    (``replace``: existing files are not the question, only the other rules)."""
    from userio.outputs import Outputs

    plan = Outputs(force=args.force or replace)
    plan.input("data", args.data)
    plan.file("--out", out)
    if not args.no_report:
        md, corner, resid = report_paths(out)
        plan.file("report (--out with .md)", md)
        plan.file("corner plot", corner)
        plan.file("residual plot", resid)
    return plan


def run(args) -> int:
    from userio.errors import InputError
    from calibration.session import LEVER_ARM_RANGE_M, MASS_RANGE_G

    from userio.errors import finite, seed

    if args.lever_arm_m is not None:
        args.lever_arm_m = LEVER_ARM_RANGE_M.check(args.lever_arm_m, "--lever-arm-m")
    args.mass_std_g = finite(args.mass_std_g, "--mass-std-g", nonneg=True)
    MASS_RANGE_G.check(args.mass_std_g, "--mass-std-g")
    seed(args.seed)
    if args.walkers < 8:
        raise InputError(f"--walkers: need at least 8, got {args.walkers}")
    if args.max_steps < 1:
        raise InputError(f"--max-steps: must be ≥ 1, got {args.max_steps}")
    _plan(args, args.out, replace=True).check()      # the names given: never the data, dirs made
    # the name written: --out, or its first free NAME.vK.json without --force (kept, never replaced)
    written = _target(args.out, args.force, args.no_report)
    plan = _plan(args, written)
    plan.check()            # before the fit: outputs vs input, directories made, room to write
    with plan.active():
        return _calibrate(args, written)


def _calibrate(args, written: Path) -> int:
    from userio.errors import InputError
    from calibration.fit import fit_session
    from calibration.session import read_session
    from calibration.store import calibration_payload, encode
    from torquebench.io import print_json
    from userio.files import write_files_atomic

    session = read_session(args.data)
    if args.lever_arm_m is not None:
        session.lever_arm_m = args.lever_arm_m
    if args.sensor_id:
        session.sensor_id = args.sensor_id
    fit = fit_session(session, args.model, mass_std_g=args.mass_std_g, seed=args.seed,
                      n_walkers=args.walkers, max_steps=args.max_steps)
    if not fit.converged:
        raise InputError(f"{args.data}: refusing to store an unconverged fit: {fit.reason} "
                         "(--max-steps)")
    payload = calibration_payload(fit, session, provenance={
        "command": "torquebench calibrate",
        "args": {"data": str(args.data), "model": args.model, "mass_std_g": args.mass_std_g,
                 "seed": args.seed, "walkers": args.walkers, "max_steps": args.max_steps,
                 "lever_arm_m": args.lever_arm_m}})
    files = [(written, encode(payload))]
    if not args.no_report:
        files += _report(payload, fit, session, written)
    write_files_atomic(files)          # calibration + report + plots, all or none (the plan decides)
    reports = [p for p, _ in files[1:]]
    versioned = written != args.out
    if versioned:
        print(f"warning: calibrate: {args.out} exists; kept it and wrote {written} (use --force to "
              "replace)", file=sys.stderr)
    post = payload["posterior"]
    unit = session.reading_unit
    keys = {n: coefficient_key(n, unit) for n in (*fit.coef_names, "sigma")}
    se = dict(zip(fit.names, fit.mc_standard_error))
    method = (f"posterior standard deviation (1σ) of the emcee fit, {fit.n_walkers} walkers × "
              f"{fit.n_steps} steps; the posterior mean's own Monte Carlo standard error is "
              f"<key>_mc_standard_error (σ_post·√(τ/N), τ = {fit.tau_max:.1f} steps, "
              f"split R̂ = {fit.rhat:.4f})")
    result = {}
    for n, key in keys.items():
        result[key] = post[n]["mean"]
        result[f"{key}_error_estimate"] = post[n]["std"]
        result[f"{key}_error_method"] = method
        if n in se:
            result[f"{key}_mc_standard_error"] = float(se[n])
    result["rhat"] = fit.rhat
    result.update({
        "r2": fit.exact.r2, "autocorr_time": fit.tau_max,
        "autocorr_time_per_parameter": dict(zip(fit.names, fit.autocorr_time)),
        "acceptance_fraction": fit.acceptance_fraction, "converged": fit.converged,
        "n_steps": fit.n_steps, "n_walkers": fit.n_walkers, "burn_in": fit.burn_in,
        "model": fit.model, "reading_unit": unit, "mass_unit": "g",
        "lever_arm_m": session.lever_arm_m,
        "exact_mean": {keys[n]: v for n, v in zip(fit.coef_names, fit.exact.beta)},
        "exact_std": {keys[n]: v for n, v in zip(fit.coef_names, fit.exact.std)},
        "characterization": payload["characterization"],
        "written": str(written), "versioned": versioned, "report": [str(p) for p in reports],
        "fit_time_s": fit.elapsed_s,
    })
    if session.lever_arm_m:
        from calibration.session import G_STANDARD_M_PER_S2
        per_Nm = 1.0 / (1e-3 * G_STANDARD_M_PER_S2 * session.lever_arm_m)     # τ of 1 g, N·m
        result[f"sensitivity_{unit}_per_Nm"] = result[keys["slope"]] * per_Nm
    if args.json:
        print_json(result)
        return 0
    print(f"{session.sensor_id}: {fit.model} fit of {len(session)} readings ({args.data})")
    ref = "exact" if args.mass_std_g == 0 else "exact without errors-in-load"
    for i, n in enumerate(fit.coef_names):
        u = coefficient_unit(n, unit)
        print(f"  {n:<11s}= {post[n]['mean']:.6g} ± {post[n]['std']:.2g} {u} (posterior σ; "
              f"MC error ± {se[n]:.2g})  ({ref} {fit.exact.beta[i]:.6g} ± {fit.exact.std[i]:.2g} {u})")
    print(f"  sigma      = {post['sigma']['mean']:.4g} ± {post['sigma']['std']:.2g} {unit};  "
          f"R² = {fit.exact.r2:.5f}")
    if session.lever_arm_m:
        print(f"  sensitivity = {result[f'sensitivity_{unit}_per_Nm']:.6g} {unit}/(N·m) "
              f"(lever arm {session.lever_arm_m:g} m)")
    print(f"  τ = {fit.tau_max:.1f} steps, {fit.n_steps} steps × {fit.n_walkers} walkers, "
          f"acceptance {fit.acceptance_fraction:.2f}, split R̂ = {fit.rhat:.4f}, converged")
    print(f"wrote {written}" + ("".join(f", {p}" for p in reports)))
    return 0
