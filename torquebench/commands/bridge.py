"""`torquebench bridge`: noise budget and minimum detectable strain/torque of a sensor config."""

from __future__ import annotations

HELP = "noise budget and minimum detectable strain/torque of a bridge + ADC (paper's by default)"
EXAMPLES = """\
torquebench bridge
torquebench bridge sensors/paper_sensor.toml --averaging 4 --json
"""


def add_arguments(parser) -> None:
    parser.add_argument("config", nargs="?", default=None, metavar="CONFIG.toml",
                        help="sensor TOML (default: sensors/paper_sensor.toml)")
    parser.add_argument("--strain-per-Nm", type=float, default=None, dest="strain_per_Nm",
                        help="gauge strain per N·m of joint torque, 1/(N·m) (default: the file's [torque] strain_per_Nm)")
    parser.add_argument("--bandwidth-Hz", type=float, default=None, dest="bandwidth_Hz",
                        help="noise bandwidth in Hz (default: one ADC sample, 0.5 × data rate)")
    parser.add_argument("--averaging", type=int, default=1,
                        help="average this many ADC samples: noise bandwidth / N (default: %(default)s)")


MAX_AVERAGING_S = 3600.0     # a reading averaged over more than an hour is a drift measurement


def _strain_range():
    from userio.ranges import Range

    return Range(1e-9, 1e-1, "1/(N·m)", low="a sensor this stiff reads nothing: µε typed as ε?",
                 high="beyond any gauge's strain range at 1 N·m")


def _fmt(v) -> str:
    return f"{v:.4g}" if isinstance(v, float) else str(v)


def run(args) -> int:
    from bridge.budget import sensor_summary
    from bridge.config import load_sensor_config
    from userio.errors import InputError
    from torquebench.io import print_json, shipped

    from userio.errors import finite

    from userio.ranges import Range

    STRAIN_PER_NM = _strain_range()
    if args.strain_per_Nm is not None:
        finite(args.strain_per_Nm, "--strain-per-Nm", positive=True)
        STRAIN_PER_NM.check(args.strain_per_Nm, "--strain-per-Nm")
    if args.bandwidth_Hz is not None:
        finite(args.bandwidth_Hz, "--bandwidth-Hz", positive=True)
        Range(1e-6, 1e9, "Hz").check(args.bandwidth_Hz, "--bandwidth-Hz")
    if args.averaging < 1:
        raise InputError(f"--averaging: must be ≥ 1, got {args.averaging}")
    path = args.config or shipped("sensors", "paper_sensor.toml")
    cfg, spn = load_sensor_config(path)
    span_s = args.averaging / cfg.data_rate_Hz
    if span_s > MAX_AVERAGING_S:
        raise InputError(f"--averaging: {args.averaging} samples at {cfg.data_rate_Hz:g} S/s span "
                         f"{span_s:.3g} s, above an hour: no sensor holds still (drift, 1/f noise) "
                         "that long; average fewer samples")
    if args.strain_per_Nm is not None:
        spn = args.strain_per_Nm
    out = sensor_summary(cfg, spn, args.bandwidth_Hz, args.averaging)
    out["config"] = str(path)
    if args.json:
        print_json(out)
        return 0
    print(f"sensor: {path}  ({cfg.arrangement}, GF {cfg.gauge_factor:g}, "
          f"{cfg.gauge_resistance_ohm:g} Ω, V_ex {cfg.excitation_V:g} V, gain {cfg.gain:g}, "
          f"{cfg.bits}-bit ADC ±{cfg.range_factor * cfg.v_ref_V:g} V, ENOB {cfg.enob:g} "
          f"({cfg.enob_definition}), {cfg.data_rate_Hz:g} S/s)")
    print(f"noise bandwidth {out['noise_bandwidth_Hz']:.4g} Hz (averaging {args.averaging})")
    print(f"{'term':<14}{'V rms':>12}{'strain':>12}" + (f"{'N·m':>12}" if spn else ""))
    for term in ("johnson", "amplifier", "adc", "quantization"):
        v, e = out[f"noise_{term}_V"], out[f"noise_{term}_strain"]
        print(f"{term:<14}{v:>12.4g}{e:>12.4g}" + (f"{e / spn:>12.4g}" if spn else ""))
    print(f"{'total':<14}{out['noise_rms_V']:>12.4g}{out['noise_rms_strain']:>12.4g}"
          + (f"{out['noise_rms_Nm']:>12.4g}" if spn else ""))
    print(f"dominant noise: {out['dominant_noise']}")
    print(f"eq. 11 (quarter bridge): eps_min ideal {out['eps_min_ideal']:.4g}, "
          f"at ENOB {out['eps_min_enob']:.4g}")
    print(f"this bridge: eps_min ideal {out['eps_min_ideal_bridge']:.4g}, at ENOB "
          f"{out['eps_min_enob_bridge']:.4g}, 1σ noise {out['eps_min_noise']:.4g}")
    print(f"ENOB {out['enob_ti']:.3f} (ti) = {out['enob_ieee']:.3f} (ieee); noise-free bits "
          f"{out['noise_free_bits']:.2f}; self-heating {out['self_heating_W_per_gauge'] * 1e3:.3g} "
          "mW/gauge")
    if spn:
        print(f"strain per N·m {spn:.4g}: sensitivity {out['sensitivity_V_per_Nm'] * 1e3:.4g} mV/N·m;"
              f" min detectable torque 1σ {out['min_detectable_torque_Nm']:.4g} ± "
              f"{out['min_detectable_torque_Nm_error_estimate']:.2g} N·m (ENOB-definition spread) "
              f"(resolution: ideal {out['min_detectable_torque_ideal_Nm']:.3g}, "
              f"ENOB {out['min_detectable_torque_enob_Nm']:.3g} N·m)")
    return 0
