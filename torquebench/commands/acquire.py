"""`torquebench acquire`: record the ADC stream over serial (raw bytes first), optionally guided."""

from __future__ import annotations

import sys
from pathlib import Path

HELP = "record the ADC frame stream from a serial port (or guided static-loading session)"
EXAMPLES = """\
torquebench acquire --port /dev/ttyACM0 --out out/capture.bin --duration-s 10 --csv out/capture.csv
torquebench acquire --port /dev/ttyACM0 --out out/link1.bin --guided 0,10,20,50,100,200,500,1000 --lever-arm-m 0.205 --sensor-id link1
"""


def add_arguments(parser) -> None:
    parser.add_argument("--port", required=True,
                        help="serial device (/dev/ttyACM0) or pyserial URL (loop://, rfc2217://...)")
    parser.add_argument("--baud", type=int, default=2_000_000,
                        help="serial baud rate in bit/s (default: %(default)s)")
    parser.add_argument("--out", type=Path, required=True, help="raw byte capture file to write (its directory is created; never replaced without --force)")
    parser.add_argument("--channels", type=int, default=1, help="channels per frame, 1–8 (default: %(default)s)")
    parser.add_argument("--duration-s", type=float, default=None, help="stop after this many seconds (default: no time limit)")
    parser.add_argument("--frames", type=int, default=None, help="stop after this many frames (default: no frame limit)")
    parser.add_argument("--idle-timeout-s", type=float, default=2.0,
                        help="stop when no bytes arrive for this many seconds (default: %(default)s)")
    parser.add_argument("--csv", type=Path, default=None, help="also write the decoded samples to this CSV (ADC counts per channel)")
    parser.add_argument("--guided", default=None, metavar="MASSES_G",
                        help="guided static-loading session: comma-separated masses in grams, e.g. 0,10,20,50,100")
    parser.add_argument("--session", type=Path, default=None,
                        help="guided: session CSV to write (default: the --out file with .csv)")
    parser.add_argument("--repeats", type=int, default=1,
                        help="guided: times to walk through the masses (default: %(default)s)")
    parser.add_argument("--unload", action="store_true", help="guided: also walk back down")
    parser.add_argument("--rate-hz", type=float, default=4000.0, help="nominal ADC sample rate in Hz (default: %(default)s)")
    parser.add_argument("--settle-s", type=float, default=2.0,
                        help="guided: seconds to wait after a mass is hung before averaging (default: %(default)s)")
    parser.add_argument("--window-s", type=float, default=1.0,
                        help="guided: seconds of readings averaged per mass (default: %(default)s)")
    parser.add_argument("--channel", type=int, default=0, help="guided: channel to average, 0-based (default: %(default)s)")
    parser.add_argument("--sensor-id", default="sensor",
                        help="guided: sensor name written into the session CSV (default: %(default)s)")
    parser.add_argument("--lever-arm-m", type=float, default=None,
                        help="guided: lever arm in m from the joint axis to the hanging masses, written into the session CSV (default: not recorded)")
    parser.add_argument("--tolerance-counts", type=float, default=None,
                        help="guided: warn when a load step's mean reading has a standard error above this, "
                             "in ADC counts (default: no check)")
    parser.add_argument("--force", action="store_true", help="replace existing output files")


def run(args) -> int:
    from calibration.acquire import RawCapture
    from userio.errors import InputError
    from calibration.frames import MAX_CHANNELS

    from userio.errors import finite

    for name, v, hi in (("--duration-s", args.duration_s, 1e7), ("--idle-timeout-s", args.idle_timeout_s,
                        3600.0), ("--rate-hz", args.rate_hz, 1e7), ("--settle-s", args.settle_s, 3600.0),
                        ("--window-s", args.window_s, 3600.0),
                        ("--tolerance-counts", args.tolerance_counts, 1e12)):
        if v is not None:
            finite(v, name, positive=name != "--settle-s", nonneg=True, hi=hi)
    if args.lever_arm_m is not None:
        from calibration.session import LEVER_ARM_RANGE_M
        LEVER_ARM_RANGE_M.check(args.lever_arm_m, "--lever-arm-m")
    for name, v in (("--baud", args.baud), ("--repeats", args.repeats), ("--frames", args.frames)):
        if v is not None and v < 1:
            raise InputError(f"{name}: must be ≥ 1, got {v}")
    if not 1 <= args.channels <= MAX_CHANNELS:
        raise InputError(f"--channels: must be 1..{MAX_CHANNELS}, got {args.channels}")
    if not 0 <= args.channel < args.channels:
        raise InputError(f"--channel: must be 0..{args.channels - 1}")
    masses = None
    if args.guided is not None:
        try:
            masses = [float(m) for m in args.guided.split(",") if m.strip()]
        except ValueError:
            raise InputError(f"--guided: {args.guided!r} is not a comma-separated list of masses") from None
        for m in masses:
            finite(m, "--guided", nonneg=True)
        if len(set(masses)) < 2 or min(masses) < 0:
            raise InputError("--guided: need at least two distinct non-negative masses (g)")
        from calibration.session import MASS_RANGE_G
        for m in masses:
            MASS_RANGE_G.check(m, "--guided")
    from userio.outputs import Outputs

    plan = Outputs(force=args.force)
    if "://" not in str(args.port):
        plan.input("--port", args.port)
    plan.file("--out", args.out)
    plan.file("--csv", args.csv)
    plan.file("--session", (args.session or args.out.with_suffix(".csv")) if masses else None)
    plan.input("--out's kept capture (.part)", RawCapture.part_path(args.out))   # appended, never written over
    with plan.active():                     # checked now; every write obeys it
        return _acquire(args, masses)


def _acquire(args, masses) -> int:
    import numpy as np

    from userio.errors import InputError
    from calibration.acquire import RawCapture, Reader, capture, guided_session, open_port, session_csv
    from calibration.frames import FrameParser
    from torquebench.io import print_json
    from userio.files import write_files_atomic

    port = open_port(args.port, args.baud)
    raw = RawCapture(args.out, force=args.force)
    if raw.resumed:
        print(f"acquire: appending to the capture kept in {raw.part} ({raw.resumed} bytes)", file=sys.stderr)
    reader = Reader(port, raw, FrameParser(args.channels), keep=args.csv is not None)
    rows = None
    try:
        if masses is None:
            capture(reader, n_frames=args.frames, duration_s=args.duration_s,
                    idle_timeout_s=args.idle_timeout_s)
        else:
            out = sys.stderr
            rows = guided_session(reader, masses, settle_samples=int(args.settle_s * args.rate_hz),
                                  window_samples=max(int(args.window_s * args.rate_hz), 4),
                                  repeats=args.repeats, unload=args.unload, channel=args.channel,
                                  idle_timeout_s=args.idle_timeout_s,
                                  prompt=lambda msg: (print(msg, end="", file=out, flush=True),
                                                      sys.stdin.readline())[1], out=out)
    except KeyboardInterrupt:
        raw.abort()
        raise KeyboardInterrupt(f"raw bytes so far kept in {raw.part}") from None
    except InputError as exc:
        raw.abort()
        raise InputError(f"{exc}; raw bytes so far kept in {raw.part}") from None
    except BaseException:
        raw.abort()
        print(f"acquire: raw bytes so far kept in {raw.part}", file=sys.stderr)
        raise
    finally:
        port.close()
    raw_path = raw.close()
    written = [str(raw_path)]
    files = []
    if args.csv is not None and reader.seq_log:
        seq = np.concatenate(reader.seq_log)
        s = np.concatenate(reader.sample_log)
        text = "seq," + ",".join(f"ch{i}_counts" for i in range(args.channels)) + "\n"
        text += "\n".join(",".join(map(str, r)) for r in np.column_stack([seq, s]).tolist()) + "\n"
        files.append((args.csv, text))
    if rows is not None:
        spath = args.session or raw_path.with_suffix(".csv")
        files.append((spath, session_csv(rows, sensor_id=args.sensor_id,
                                         lever_arm_m=args.lever_arm_m, source=str(raw_path))))
    write_files_atomic(files)            # decoded CSV + session, all or none (the plan decides)
    written += [str(p) for p, _ in files]
    st = reader.parser.stats.as_dict()
    steps, warnings = load_steps(rows or [], args.tolerance_counts)
    if args.json:
        out = {**st, "written": written, "readings": len(rows) if rows else 0}
        if rows is not None:
            out.update(load_steps=steps, warnings=warnings)
        print_json(out)
    else:
        print(f"{st['frames']} frames, {st['corrupted']} corrupted, {st['lost']} lost, "
              f"{st['garbage_bytes']} garbage bytes of {st['bytes']}; wrote {', '.join(written)}")
        for s in steps:
            print(f"{s['mass_g']:g} g {s['direction']}: reading {s['reading_counts']:.2f} ± "
                  f"{s['reading_counts_error_estimate']:.2g} counts, noise {s['noise_std_counts']:.2f} ± "
                  f"{s['noise_std_counts_error_estimate']:.2g} counts, settling step "
                  f"{s['settle_step_counts']:.2g} ± {s['settle_step_counts_error_estimate']:.2g} counts "
                  f"(limit {s['settle_limit_counts']:.2g}; {'settled' if s['settled'] else 'NOT settled'})")
        for w in warnings:
            print(f"warning: {w}")
    return 0


def load_steps(rows: list[dict], tolerance_counts: float | None) -> tuple[list[dict], list[str]]:
    """JSON rows of a guided session (each figure with ``_error_estimate``/``_error_method``, 1σ)
    and the warnings: unsettled steps, windows too short to resolve the noise's correlation, and
    standard errors above ``--tolerance-counts``."""
    steps, warnings = [], []
    for r in rows:
        s = r["stats"]
        steps.append({
            "mass_g": r["mass_g"], "direction": r["direction"], "repeat": r["repeat"],
            "n_samples": r["n_samples"],
            "reading_counts": s["mean"], "reading_counts_error_estimate": s["mean_se"],
            "reading_counts_error_method": s["mean_se_method"],
            "noise_std_counts": s["std"], "noise_std_counts_error_estimate": s["std_se"],
            "noise_std_counts_error_method": s["std_se_method"],
            "settle_step_counts": s["step"], "settle_step_counts_error_estimate": s["step_se"],
            "settle_step_counts_error_method": s["step_se_method"],
            "settle_limit_counts": s["threshold"], "settled": bool(s["settled"]),
            "autocorr_time_samples": s["autocorr_time"], "n_effective": s["n_effective"],
        })
        where = f"{r['mass_g']:g} g {r['direction']} (repeat {r['repeat'] + 1})"
        if not s["settled"]:
            warnings.append(f"{where}: not settled (step {s['step']:.3g} counts > limit {s['threshold']:.3g}); "
                            "recorded with settled=0")
        if not s["autocorr_resolved"]:
            warnings.append(f"{where}: the window holds only {s['n_effective']:.0f} independent samples "
                            f"(τ = {s['autocorr_time']:.3g}): its error estimates are underestimates; "
                            "use a longer --window-s")
        if tolerance_counts is not None and s["mean_se"] > tolerance_counts:
            warnings.append(f"{where}: reading standard error {s['mean_se']:.3g} counts exceeds "
                            f"--tolerance-counts {tolerance_counts:g}")
    return steps, warnings
