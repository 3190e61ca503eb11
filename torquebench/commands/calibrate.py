"""`torquebench calibrate`: Bayesian (emcee) calibration of a static-loading session."""

from __future__ import annotations

import sys
from pathlib import Path

HELP = "fit calibration coefficients (emcee) to a loading-session CSV and store them safely"


def add_arguments(parser) -> None:
    parser.add_argument("data", type=Path, help="session CSV (columns mass_g,reading[,direction,...])")
    parser.add_argument("--out", type=Path, required=True, help="calibration file to write (JSON)")
    parser.add_argument("--model", choices=("linear", "quadratic", "hysteresis"), default="linear")
    parser.add_argument("--force", action="store_true",
                        help="replace an existing --out (default: keep it, write NAME.vK.json)")
    parser.add_argument("--lever-arm-m", type=float, default=None,
                        help="lever arm (m) if the CSV has no lever_arm_m column")
    parser.add_argument("--mass-std-g", type=float, default=0.0,
                        help="standard uncertainty of the applied masses (g): errors-in-load term")
    parser.add_argument("--sensor-id", default=None, help="override the CSV's sensor_id")
    parser.add_argument("--seed", type=int, default=0, help="sampler seed (reproducible fits)")
    parser.add_argument("--walkers", type=int, default=256,
                        help="emcee walkers (vectorized: many walkers cost little per step)")
    parser.add_argument("--max-steps", type=int, default=50_000,
                        help="give up (and refuse to store) if not converged by then")
    parser.add_argument("--no-report", action="store_true",
                        help="skip the Markdown report and corner/residual plots beside --out")


def _report(doc: dict, fit, session, out: Path) -> list[Path]:
    from calibration.plots import corner_plot, residual_plot
    from torquebench.io import atomic_path, write_text_atomic

    stem = out.with_suffix("")
    corner_png = stem.with_name(stem.name + "_corner.png")
    resid_png = stem.with_name(stem.name + "_residuals.png")
    with atomic_path(corner_png) as tmp:
        corner_plot(fit, tmp, title=f"{session.sensor_id}: {fit.model}")
    with atomic_path(resid_png) as tmp:
        residual_plot(session, fit, tmp)
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
    md = stem.with_name(stem.name + ".md")
    write_text_atomic(md, "\n".join(lines))
    return [md, corner_png, resid_png]


def run(args) -> int:
    from calibration.errors import InputError
    from calibration.fit import fit_session
    from calibration.session import read_session
    from calibration.store import calibration_payload, save
    from torquebench.io import print_json

    if args.lever_arm_m is not None and not args.lever_arm_m > 0:
        raise InputError(f"--lever-arm-m: must be > 0, got {args.lever_arm_m:g}")
    if args.walkers < 8:
        raise InputError(f"--walkers: need at least 8, got {args.walkers}")
    if not args.out.parent.is_dir():
        raise InputError(f"--out: directory {args.out.parent} does not exist")
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
    written = save(payload, args.out, force=args.force)
    versioned = written != args.out
    if versioned:
        print(f"calibrate: {args.out} exists; kept it and wrote {written} (use --force to replace)",
              file=sys.stderr)
    reports = [] if args.no_report else _report(payload, fit, session, written)
    post = payload["posterior"]
    result = {n: post[n]["mean"] for n in fit.coef_names}
    result.update({f"{n}_std": post[n]["std"] for n in fit.coef_names})
    se = dict(zip(fit.names, fit.mc_standard_error))
    method = (f"Monte Carlo standard error (1 sigma) of the posterior mean, sigma_post*sqrt(tau/N), "
              f"N = {fit.samples.shape[0]} samples, tau = {fit.tau_max:.1f} steps, split R-hat = {fit.rhat:.4f}")
    result.update({f"{n}_error_estimate": float(se[n]) for n in fit.coef_names})
    result.update({f"{n}_error_method": method for n in fit.coef_names})
    result["rhat"] = fit.rhat
    result.update({
        "sigma": post["sigma"]["mean"], "sigma_std": post["sigma"]["std"],
        "r2": fit.exact.r2, "autocorr_time": fit.tau_max,
        "autocorr_time_per_parameter": dict(zip(fit.names, fit.autocorr_time)),
        "acceptance_fraction": fit.acceptance_fraction, "converged": fit.converged,
        "n_steps": fit.n_steps, "n_walkers": fit.n_walkers, "burn_in": fit.burn_in,
        "model": fit.model, "reading_unit": session.reading_unit, "mass_unit": "g",
        "lever_arm_m": session.lever_arm_m,
        "exact_mean": dict(zip(fit.coef_names, fit.exact.beta)),
        "exact_std": dict(zip(fit.coef_names, fit.exact.std)),
        "characterization": payload["characterization"],
        "written": str(written), "versioned": versioned, "report": [str(p) for p in reports],
        "fit_time_s": fit.elapsed_s,
    })
    if session.lever_arm_m:
        per_Nm = 1.0 / (1e-3 * 9.80665 * session.lever_arm_m)
        result["sensitivity_per_Nm"] = result["slope"] * per_Nm
    if args.json:
        print_json(result)
        return 0
    unit = session.reading_unit
    print(f"{session.sensor_id}: {fit.model} fit of {len(session)} readings ({args.data})")
    ref = "exact" if args.mass_std_g == 0 else "exact without errors-in-load"
    for n in fit.coef_names:
        print(f"  {n:<11s}= {post[n]['mean']:.6g} ± {post[n]['std']:.2g} (posterior σ; MC error "
              f"± {result[n + '_error_estimate']:.2g})  "
              f"({ref} {fit.exact.beta[list(fit.coef_names).index(n)]:.6g} ± "
              f"{fit.exact.std[list(fit.coef_names).index(n)]:.2g})")
    print(f"  sigma      = {post['sigma']['mean']:.4g} {unit};  R² = {fit.exact.r2:.5f}")
    print(f"  τ = {fit.tau_max:.1f} steps, {fit.n_steps} steps × {fit.n_walkers} walkers, "
          f"acceptance {fit.acceptance_fraction:.2f}, split R̂ = {fit.rhat:.4f}, converged")
    print(f"wrote {written}" + ("".join(f", {p}" for p in reports)))
    return 0
