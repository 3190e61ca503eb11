"""Noise budget of bridge → amplifier → ADC and the minimum detectable strain / torque.

Every term is an rms voltage referred to the bridge output (amplifier input), over the noise
bandwidth B = (bandwidth_Hz or ENBW of one ADC sample) / averaging:

- johnson       √(4 k_B T R_out B), R_out = R (+ lead) for a balanced bridge
- amplifier     e_n √((B − f_lo) + f_c ln(B / f_lo))   (white + 1/f from f_lo to B)
- adc           √(σ_ENOB² − σ_q²) · √(B / B_s) / G     (ENOB noise without its quantization part)
- quantization  (LSB/√12) · √(B / B_s) / G              (averages down only when dithered,
                                                        i.e. the other noise ≥ LSB/2; else LSB/√12/G)

B_s = noise_bandwidth_factor · data rate (one sample). Terms add in quadrature; strain =
V / (s GF_eff V_ex), torque = strain / strain_per_Nm.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from bridge import adc as _adc
from bridge.config import SensorConfig
from userio.errors import InputError
from bridge.wheatstone import output_resistance_ohm, sensitivity_factor

BOLTZMANN_J_PER_K = 1.380649e-23


def johnson_density_V_per_rtHz(resistance_ohm: float, temperature_K: float = 300.0) -> float:
    """√(4 k_B T R): 4.07 nV/√Hz for 1 kΩ at 300 K."""
    if resistance_ohm <= 0 or temperature_K <= 0:
        raise InputError("johnson noise: resistance and temperature must be > 0")
    return math.sqrt(4.0 * BOLTZMANN_J_PER_K * temperature_K * resistance_ohm)


def amplifier_noise_rms_V(noise_V_per_rtHz: float, corner_Hz: float, bandwidth_Hz: float,
                          f_low_Hz: float = 0.1) -> float:
    """e_n √((B − f_lo) + f_c ln(B/f_lo)): ∫ e_n² (1 + f_c/f) df from f_lo to B."""
    if noise_V_per_rtHz == 0.0 or bandwidth_Hz <= f_low_Hz:
        return 0.0
    return noise_V_per_rtHz * math.sqrt((bandwidth_Hz - f_low_Hz)
                                        + corner_Hz * math.log(bandwidth_Hz / f_low_Hz))


@dataclass(frozen=True)
class NoiseBudget:
    """Noise terms (V rms at the bridge output), totals and their strain/torque equivalents."""

    terms_V: dict
    total_V: float
    bandwidth_Hz: float
    sensitivity_V_per_strain: float
    strain_per_Nm: float | None
    terms_strain: dict = field(default_factory=dict)
    total_strain: float = math.nan
    total_Nm: float = math.nan
    dominant: str = ""

    def to_dict(self) -> dict:
        """Flat dict, SI units, keys carry the unit."""
        out = {"noise_bandwidth_Hz": self.bandwidth_Hz, "noise_rms_V": self.total_V,
               "noise_rms_strain": self.total_strain, "dominant_noise": self.dominant,
               "bridge_sensitivity_V_per_strain": self.sensitivity_V_per_strain}
        for k, v in self.terms_V.items():
            out[f"noise_{k}_V"] = v
            out[f"noise_{k}_strain"] = self.terms_strain[k]
        if self.strain_per_Nm is not None:
            out["strain_per_Nm"] = self.strain_per_Nm
            out["noise_rms_Nm"] = self.total_Nm
        return out


def _bandwidth(cfg: SensorConfig, bandwidth_Hz, averaging) -> float:
    if isinstance(averaging, bool) or int(averaging) != averaging or averaging < 1:
        raise InputError(f"averaging: must be an integer >= 1, got {averaging!r}")
    b_s = cfg.noise_bandwidth_Hz
    if bandwidth_Hz is None:
        b = b_s
    else:
        b = float(bandwidth_Hz)
        if not math.isfinite(b) or b <= 0:
            raise InputError(f"bandwidth_Hz: must be > 0, got {bandwidth_Hz}")
        if b > b_s * (1 + 1e-12):
            raise InputError(f"bandwidth_Hz: {b:g} Hz exceeds the ADC sample's noise bandwidth "
                             f"{b_s:g} Hz (noise_bandwidth_factor × data_rate_Hz)")
    return b / int(averaging)


def noise_budget(config: SensorConfig | None = None, strain_per_Nm: float | None = None,
                 bandwidth_Hz: float | None = None, averaging: int = 1) -> NoiseBudget:
    """Quadrature noise budget (module docstring) over B = (bandwidth_Hz or B_s)/averaging."""
    cfg = config if config is not None else SensorConfig()
    b = _bandwidth(cfg, bandwidth_Hz, averaging)
    b_s = cfg.noise_bandwidth_Hz
    g = cfg.gain
    r_out = output_resistance_ohm(cfg.gauge_resistance_ohm, cfg.lead_resistance_ohm)
    johnson = johnson_density_V_per_rtHz(r_out, cfg.temperature_K) * math.sqrt(b)
    amp = amplifier_noise_rms_V(cfg.noise_V_per_rtHz, cfg.corner_Hz, b, cfg.flicker_low_Hz)
    sigma_q = _adc.quantization_noise_rms_V(cfg.lsb_V)
    sigma_adc = math.sqrt(max(cfg.adc_noise_rms_V ** 2 - sigma_q ** 2, 0.0))
    scale = math.sqrt(b / b_s)
    other_at_adc = math.sqrt((g * johnson / scale) ** 2 + (g * amp / scale) ** 2 + sigma_adc ** 2)
    dithered = other_at_adc >= 0.5 * cfg.lsb_V
    terms = {"johnson": johnson, "amplifier": amp, "adc": sigma_adc * scale / g,
             "quantization": sigma_q * (scale if dithered else 1.0) / g}
    total = math.sqrt(sum(v * v for v in terms.values()))
    sens = cfg.bridge_sensitivity_V_per_strain
    terms_strain = {k: v / sens for k, v in terms.items()}
    total_strain = total / sens
    total_Nm = total_strain / strain_per_Nm if strain_per_Nm else math.nan
    dominant = max(terms, key=terms.get)
    return NoiseBudget(terms, total, b, sens, strain_per_Nm, terms_strain, total_strain,
                       total_Nm, dominant)


def eps_min_eq11(n_bits: float, v_ref_V: float = 2.5, gauge_factor: float = 2.0,
                 excitation_V: float = 5.0) -> float:
    """Paper eq. 11: ε_min = 4 V_ref / (GF V_ex 2^N) (quarter bridge, resolution V_ref/2^N)."""
    return 4.0 * v_ref_V / (gauge_factor * excitation_V * 2.0 ** n_bits)


def min_detectable_strain(config: SensorConfig | None = None, *, method: str = "resolution",
                          n_bits: float | None = None, arrangement: str | None = None,
                          bandwidth_Hz: float | None = None, averaging: int = 1,
                          k_sigma: float = 1.0) -> float:
    """Smallest detectable reference-gauge strain.

    method="resolution" (paper eq. 11 generalized): ε = (V_ref/2^N)/G / (s GF_eff V_ex), with
      N = ``n_bits`` (default config.bits: "ideal"; pass the ENOB for the paper's 1.53e-5) and s the
      arrangement's sensitivity factor (1/4 quarter → eq. 11 exactly, 1/2 half, 1 full bending).
    method="noise": ε = k_sigma · σ_total / (s GF_eff V_ex) from :func:`noise_budget` over
      (bandwidth_Hz or one sample's ENBW) / averaging.
    """
    cfg = config if config is not None else SensorConfig()
    if arrangement is not None:
        cfg = cfg.replace(arrangement=arrangement)
    if method == "resolution":
        if bandwidth_Hz is not None or averaging != 1:
            raise InputError("min_detectable_strain: bandwidth_Hz/averaging act on noise; "
                             "use method='noise' (a noiseless resolution step does not average)")
        n = cfg.bits if n_bits is None else float(n_bits)
        if n <= 0:
            raise InputError(f"n_bits: must be > 0, got {n_bits}")
        v_res = cfg.v_ref_V / 2.0 ** n / cfg.gain
        return v_res / cfg.bridge_sensitivity_V_per_strain
    if method == "noise":
        if k_sigma <= 0:
            raise InputError(f"k_sigma: must be > 0, got {k_sigma}")
        return k_sigma * noise_budget(cfg, None, bandwidth_Hz, averaging).total_strain
    raise InputError(f"method: must be 'resolution' or 'noise', got {method!r}")


def min_detectable_torque_Nm(strain_per_Nm: float, config: SensorConfig | None = None,
                             **kwargs) -> float:
    """min_detectable_strain(...) / strain_per_Nm."""
    if not strain_per_Nm or strain_per_Nm <= 0:
        raise InputError(f"strain_per_Nm: must be > 0, got {strain_per_Nm}")
    return min_detectable_strain(config, **kwargs) / strain_per_Nm


def sensor_summary(config: SensorConfig | None = None, strain_per_Nm: float | None = None,
                   bandwidth_Hz: float | None = None, averaging: int = 1) -> dict:
    """Everything ``torquebench bridge`` prints: ε_min (eq. 11 and this bridge), budget, ADC figures.

    eps_min_ideal / eps_min_enob: eq. 11 exactly (quarter-bridge form, N = bits / ENOB);
    eps_min_*_bridge: the same resolution argument for the configured arrangement and gain;
    eps_min_noise: 1σ noise over the bandwidth (the physically meaningful floor).
    """
    from bridge.wheatstone import self_heating_W

    cfg = config if config is not None else SensorConfig()
    bud = noise_budget(cfg, strain_per_Nm, bandwidth_Hz, averaging)
    enob_ti = _adc.convert_enob(cfg.enob, cfg.enob_definition, "ti")
    out = {
        "arrangement": cfg.arrangement,
        "eps_min_ideal": eps_min_eq11(cfg.bits, cfg.v_ref_V, cfg.gauge_factor, cfg.excitation_V),
        "eps_min_enob": eps_min_eq11(cfg.enob, cfg.v_ref_V, cfg.gauge_factor, cfg.excitation_V),
        "eps_min_ideal_bridge": min_detectable_strain(cfg),
        "eps_min_enob_bridge": min_detectable_strain(cfg, n_bits=cfg.enob),
        "eps_min_noise": bud.total_strain,
        "enob_ti": enob_ti,
        "enob_ieee": _adc.convert_enob(cfg.enob, cfg.enob_definition, "ieee"),
        "noise_free_bits": _adc.noise_free_bits(cfg.adc_noise_rms_V, cfg.fsr_V),
        "adc_lsb_V": cfg.lsb_V,
        "adc_full_scale_range_V": cfg.fsr_V,
        "adc_noise_rms_V": cfg.adc_noise_rms_V,
        "johnson_density_V_per_rtHz": johnson_density_V_per_rtHz(
            output_resistance_ohm(cfg.gauge_resistance_ohm, cfg.lead_resistance_ohm),
            cfg.temperature_K),
        "self_heating_W_per_gauge": self_heating_W(cfg.excitation_V, cfg.gauge_resistance_ohm),
        "averaging": int(averaging),
    }
    out.update(bud.to_dict())
    if strain_per_Nm:
        out["sensitivity_V_per_Nm"] = bud.sensitivity_V_per_strain * strain_per_Nm
        out["sensitivity_mV_per_V_per_Nm"] = out["sensitivity_V_per_Nm"] / cfg.excitation_V * 1e3
        out["min_detectable_torque_Nm"] = bud.total_Nm
        out["min_detectable_torque_ideal_Nm"] = out["eps_min_ideal_bridge"] / strain_per_Nm
        out["min_detectable_torque_enob_Nm"] = out["eps_min_enob_bridge"] / strain_per_Nm
        est, how = _enob_definition_spread(cfg, strain_per_Nm, bandwidth_Hz, averaging, bud.total_Nm)
        out["min_detectable_torque_Nm_error_estimate"] = est
        out["min_detectable_torque_Nm_error_method"] = how
    return out


def _enob_definition_spread(cfg: SensorConfig, strain_per_Nm, bandwidth_Hz, averaging, value: float):
    """|Δ| of the 1σ noise floor when the datasheet ENOB is read under the other definition.

    The ADC noise term is σ_ADC = FSR / (2^ENOB √12) ('ti') or with the sine-wave 1.76 dB
    ('ieee'); a datasheet often does not say which. The other model terms (Johnson, amplifier,
    quantization) are taken as exact, so this is the spread from that one ambiguity, not a bound.
    """
    from dataclasses import replace as _replace

    spread = 0.0
    for other in ("ti", "ieee"):
        if other == cfg.enob_definition:
            continue
        alt = noise_budget(_replace(cfg, enob_definition=other), strain_per_Nm, bandwidth_Hz, averaging)
        spread = max(spread, abs(alt.total_Nm - value))
    return spread, ("spread from the ENOB-definition ambiguity (same datasheet ENOB read as 'ti' vs "
                    "'ieee'); Johnson, amplifier and quantization terms taken as exact - not a bound")
