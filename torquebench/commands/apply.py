"""`torquebench apply`: convert raw readings to torque with a stored calibration."""

from __future__ import annotations

from pathlib import Path

HELP = "apply a calibration file to a CSV of readings: torque (N·m) with its uncertainty"
EXAMPLES = """\
torquebench apply calibration/data/paper_link1_cal.json calibration/data/paper_link1_readings.csv
torquebench apply calibration/data/paper_link1_cal.json calibration/data/paper_link1_readings.csv --out out/torque.csv
"""


def add_arguments(parser) -> None:
    parser.add_argument("calibration", type=Path, help="calibration JSON written by `torquebench calibrate`")
    parser.add_argument("readings", type=Path, help="CSV with a `reading` column (optional `direction`)")
    parser.add_argument("--out", type=Path, default=None,
                        help="write the readings with mass_g, mass_std_g, torque_Nm, torque_std_Nm columns to this CSV (default: print a summary only)")
    parser.add_argument("--column", default="reading", help="name of the reading column, in the calibration's reading unit (default: %(default)s)")
    parser.add_argument("--data", type=Path, default=None,
                        help="verify (by SHA-256) that the calibration was fitted to this session CSV")
    parser.add_argument("--force", action="store_true", help="replace an existing --out file")
    parser.add_argument("--coefficients-only", action="store_true",
                        help="uncertainty from the coefficients alone (leave out the reading noise σ)")


def run(args) -> int:
    from userio.outputs import Outputs

    plan = Outputs(force=args.force)
    plan.input("calibration", args.calibration)
    plan.input("readings", args.readings)
    plan.input("--data", args.data)
    plan.file("--out", args.out)
    with plan.active():                         # checked now; the write obeys it
        return _apply(args, plan)


def _apply(args, plan) -> int:
    import io

    import numpy as np
    import pandas as pd

    import calibration
    from userio.errors import InputError
    from torquebench.io import print_json
    from userio.files import write_text_atomic

    from calibration.session import MAX_SESSION_BYTES, _parse_meta
    from userio.files import check_input

    model = calibration.load(args.calibration, data_path=args.data)
    check_input(args.readings, max_bytes=16 * MAX_SESSION_BYTES, what="readings CSV")
    try:
        with open(args.readings, encoding="utf-8", errors="replace") as fh:
            n_comment, comments = 0, []
            for line in fh:
                if not line.startswith("#"):
                    break
                n_comment += 1
                comments.append(line)
        unit = _parse_meta(comments).get("reading_unit")
        if unit is not None and model.reading_unit and unit != model.reading_unit:
            raise InputError(f"{args.readings}: reading_unit={unit} but {args.calibration} converts "
                             f"readings in {model.reading_unit!r}: a unit mismatch (readings in "
                             f"{unit} through a {model.reading_unit} calibration); use a calibration "
                             f"fitted to {unit} readings")
        df = pd.read_csv(args.readings, dtype=str, keep_default_na=False, skiprows=n_comment)
    except (pd.errors.ParserError, pd.errors.EmptyDataError) as exc:
        raise InputError(f"{args.readings}: not a valid CSV: {str(exc).splitlines()[0]}") from None
    df.columns = [c.strip() for c in df.columns]
    if args.column not in df.columns:
        raise InputError(f"{args.readings}: line {n_comment + 1}: missing column {args.column!r}")
    vals = pd.to_numeric(df[args.column].str.strip(), errors="coerce").to_numpy(float)
    bad = ~np.isfinite(vals)
    if bad.any():
        i = int(np.argmax(bad))
        raise InputError(f"{args.readings}: line {i + n_comment + 2}: column {args.column!r}: "
                         f"{df[args.column].iloc[i]!r} is not a finite number")
    _check_magnitude(vals, model, args)
    direction = None
    if "direction" in df.columns and model.model == "hysteresis":
        direction = df["direction"].str.strip().str.lower().to_numpy()
        badd = ~np.isin(direction, ["load", "unload"])
        if badd.any():
            i = int(np.argmax(badd))
            raise InputError(f"{args.readings}: line {i + n_comment + 2}: column 'direction': "
                             f"{direction[i]!r} is not 'load' or 'unload'")
    out = df.copy()
    flags = model.flags(vals, direction)
    use = np.where(flags == "", 1.0, np.nan)        # flagged readings: NaN, never extrapolated
    out["mass_g"] = model.mass_g(vals, direction) * use
    noise = not args.coefficients_only
    out["mass_std_g"] = model.mass_std_g(vals, direction, include_noise=noise) * use
    if model.lever_arm_m is not None:
        out["torque_Nm"] = model.torque(vals, direction) * use
        out["torque_std_Nm"] = model.torque_std(vals, direction, include_noise=noise) * use
    out["flag"] = flags
    n_sat = int(np.count_nonzero(flags == "saturated_adc"))
    n_range = int(np.count_nonzero(flags == "outside_calibrated_range"))
    n_nan = int(np.count_nonzero(~np.isfinite(out["mass_g"].to_numpy(float))))
    buf = io.StringIO()
    out.to_csv(buf, index=False, float_format="%.9g")
    if args.out is not None:
        write_text_atomic(args.out, buf.getvalue())          # the output plan decides (--force)
    if args.json:
        res = {"n": int(vals.size), "sensor_id": model.sensor_id, "model": model.model,
               "out_of_range": n_nan, "saturated_adc": n_sat, "outside_calibrated_range": n_range,
               "calibrated_mass_range_g": list(model.mass_range_g) if model.mass_range_g else None,
               "written": str(args.out) if args.out else None,
               "mass_g": out["mass_g"].to_numpy(float), "mass_std_g": out["mass_std_g"].to_numpy(float)}
        if "torque_Nm" in out:
            res["torque_Nm"] = out["torque_Nm"].to_numpy(float)
            res["torque_std_Nm"] = out["torque_std_Nm"].to_numpy(float)
            res["torque_Nm_error_estimate"] = res["torque_std_Nm"]
            res["torque_Nm_error_method"] = (
                "per-sample 1 sigma from the stored posterior samples" + (" and the reading noise"
                                                                          if noise else " (coefficients only)"))
        res["mass_g_error_estimate"] = res["mass_std_g"]
        res["mass_g_error_method"] = ("per-sample 1 sigma from the stored posterior samples"
                                      + (" and the reading noise" if noise else " (coefficients only)"))
        print_json(res)
    elif args.out is None:
        print(_summary(out, model, vals.size, n_nan, n_sat, n_range))
    else:
        print(f"wrote {args.out} ({vals.size} readings" +
              (f", {n_nan} flagged and left NaN: {n_sat} saturated ADC, {n_range} outside the "
               "calibrated range" if n_nan else "") + ")")
    return 0


def _summary(out, model, n: int, n_nan: int, n_sat: int, n_range: int) -> str:
    """The readings in a few lines: what came out and how sure it is (the per-reading table goes
    to --out or --json)."""
    import numpy as np

    col, unit = ("torque_Nm", "N·m") if "torque_Nm" in out else ("mass_g", "g")
    v = out[col].to_numpy(float)
    sd = out[col.replace("_Nm", "_std_Nm").replace("mass_g", "mass_std_g")].to_numpy(float)
    ok = np.isfinite(v)
    lines = [f"{n} readings through {model.sensor_id} ({model.model} calibration)"]
    if ok.any():
        lines.append(f"  {col}: {v[ok].min():.4g} … {v[ok].max():.4g} {unit}, per-reading 1σ "
                     f"{sd[ok].min():.3g} … {sd[ok].max():.3g} {unit}")
    if n_nan:
        lines.append(f"  {n_nan} flagged and left NaN: {n_sat} saturated ADC, {n_range} outside the "
                     "calibrated range")
    lines.append("  the per-reading table: --out FILE.csv (or --json)")
    return "\n".join(lines)


def _check_magnitude(vals, model, args) -> None:
    """Readings that are, nearly all of them, orders of magnitude off the calibrated reading span (counts
    read through an mV calibration, V through mV, ...) are a unit mismatch, refused naming it
    rather than answered with NaN (outside the calibrated range) for every reading."""
    import numpy as np

    from userio.errors import InputError

    if model.mass_range_g is None or vals.size == 0:
        return
    lo, hi = model.mass_range_g
    r = model.coef_mean[0] * np.array([lo, hi]) + model.coef_mean[1]
    span = max(float(np.ptp(r)), float(np.abs(r).max()), 1e-300)
    typical = float(np.median(np.abs(vals)))
    ratio = typical / span
    off = (np.abs(vals) > 100 * span) | (np.abs(vals) < 1e-4 * span)
    if np.mean(off) >= 0.9:                  # (nearly) every reading: one reading off is flagged
        raise InputError(f"{args.readings}: column {args.column!r}: the readings (median |reading| "
                         f"{typical:.4g}) are {ratio:.3g} × the calibrated span of {args.calibration} "
                         f"({r.min():.4g}–{r.max():.4g} {model.reading_unit}): a unit mismatch (e.g. ADC "
                         f"counts read through an {model.reading_unit} calibration)?")
