"""Sensor configuration (bridge + amplifier + ADC), from TOML or a dict, validated.

TOML layout (every key optional; defaults are the paper's sensor, ``sensors/paper_sensor.toml``)::

    [bridge]      arrangement, gauge_factor, gauge_resistance_ohm, lead_resistance_ohm,
                  excitation_V, poisson_ratio, strain_limit, rated_strain
    [amplifier]   gain, noise_V_per_rtHz, corner_Hz, offset_V, flicker_low_Hz
    [adc]         bits, v_ref_V, range_factor (1: ±V_ref, 2: ±2 V_ref), enob, enob_definition
                  ("ti" | "ieee"), enob_data_rate_Hz, data_rate_Hz, noise_bandwidth_factor
    [environment] temperature_K
    [torque]      strain_per_Nm   (gauge strain ε per N·m; optional)

Bad values raise ``bridge.errors.InputError`` naming ``file: section.key``.
"""

from __future__ import annotations

import dataclasses
import math
import os
from dataclasses import dataclass, fields
from pathlib import Path

from bridge import adc as _adc
from bridge.errors import InputError
from userio.files import read_toml
from bridge.wheatstone import ARRANGEMENTS, effective_gauge_factor, sensitivity_factor


@dataclass(frozen=True)
class SensorConfig:
    """One strain-gauge sensor: bridge → (amplifier) → ADC. SI units throughout."""

    # bridge
    arrangement: str = "full_bending"
    gauge_factor: float = 2.0
    gauge_resistance_ohm: float = 1000.0
    lead_resistance_ohm: float = 0.0
    excitation_V: float = 5.0
    poisson_ratio: float = 0.33
    strain_limit: float = 0.03
    rated_strain: float = 1.0e-3          # reference-gauge strain at rated load (saturation check)
    # amplifier (gain 1 and zero noise = no amplifier, bridge straight into the ADC)
    gain: float = 1.0
    noise_V_per_rtHz: float = 0.0         # input-referred white voltage noise density
    corner_Hz: float = 0.0                # 1/f corner frequency
    offset_V: float = 0.0                 # input-referred offset
    flicker_low_Hz: float = 0.1           # lower integration limit of 1/f noise (1/observation time)
    # ADC
    bits: int = 24
    v_ref_V: float = 2.5
    range_factor: float = 1.0
    enob: float = 16.0
    enob_definition: str = "ti"
    enob_data_rate_Hz: float | None = None   # data rate at which ENOB holds (None: data_rate_Hz)
    data_rate_Hz: float = 4000.0
    noise_bandwidth_factor: float = 0.5      # ENBW of one output sample = factor · data rate
    # environment
    temperature_K: float = 300.0

    def __post_init__(self):
        validate(self)

    # ---- derived quantities -------------------------------------------------------------
    @property
    def gauge_factor_eff(self) -> float:
        """GF · R/(R + R_lead)."""
        return effective_gauge_factor(self.gauge_factor, self.gauge_resistance_ohm,
                                      self.lead_resistance_ohm)

    @property
    def bridge_sensitivity_V_per_strain(self) -> float:
        """dV_o/dε at zero strain: s · GF_eff · V_ex (s = 1/4 quarter … 1 full bending)."""
        return (sensitivity_factor(self.arrangement, self.poisson_ratio) * self.gauge_factor_eff
                * self.excitation_V)

    @property
    def fsr_V(self) -> float:
        return _adc.full_scale_range_V(self.v_ref_V, self.range_factor)

    @property
    def lsb_V(self) -> float:
        return _adc.lsb_V(self.bits, self.v_ref_V, self.range_factor)

    @property
    def noise_bandwidth_Hz(self) -> float:
        """ENBW of one output sample."""
        return self.noise_bandwidth_factor * self.data_rate_Hz

    @property
    def adc_noise_rms_V(self) -> float:
        """ADC total input noise (incl. quantization) at data_rate_Hz: σ(ENOB)·√(f/f_ENOB), ≥ LSB/√12."""
        f_ref = self.enob_data_rate_Hz or self.data_rate_Hz
        sigma = _adc.noise_rms_from_enob(self.enob, self.fsr_V, self.enob_definition)
        sigma *= math.sqrt(self.data_rate_Hz / f_ref)
        return max(sigma, _adc.quantization_noise_rms_V(self.lsb_V))

    def replace(self, **changes) -> "SensorConfig":
        """A copy with some fields changed (validated)."""
        unknown = set(changes) - {f.name for f in fields(self)}
        if unknown:
            raise InputError(f"unknown sensor parameter(s): {', '.join(sorted(unknown))}")
        return dataclasses.replace(self, **changes)


_SECTIONS = {
    "bridge": ("arrangement", "gauge_factor", "gauge_resistance_ohm", "lead_resistance_ohm",
               "excitation_V", "poisson_ratio", "strain_limit", "rated_strain"),
    "amplifier": ("gain", "noise_V_per_rtHz", "corner_Hz", "offset_V", "flicker_low_Hz"),
    "adc": ("bits", "v_ref_V", "range_factor", "enob", "enob_definition", "enob_data_rate_Hz",
            "data_rate_Hz", "noise_bandwidth_factor"),
    "environment": ("temperature_K",),
}
_SECTION_OF = {key: sec for sec, keys in _SECTIONS.items() for key in keys}


def _field(name: str) -> str:
    return f"{_SECTION_OF.get(name, '?')}.{name}"


def _num(cfg, name, *, positive=False, nonneg=False, finite=True):
    v = getattr(cfg, name)
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise InputError(f"{_field(name)}: must be a number, got {v!r}")
    if finite and not math.isfinite(v):
        raise InputError(f"{_field(name)}: must be finite, got {v}")
    if positive and not v > 0:
        raise InputError(f"{_field(name)}: must be > 0, got {v}")
    if nonneg and not v >= 0:
        raise InputError(f"{_field(name)}: must be >= 0, got {v}")
    return v


def _ranges():
    """Physical range of each field, with its unit (userio.fields.Range)."""
    from userio.fields import Range

    return {
        "gauge_factor": Range(0.1, 1000.0, ""), "gauge_resistance_ohm": Range(1.0, 1e7, "Ω", high="mΩ typed as Ω?"),
        "lead_resistance_ohm": Range(0.0, 1e4, "Ω"),
        "excitation_V": Range(1e-3, 100.0, "V", high="mV typed as V?"),
        "gain": Range(1e-3, 1e6, "V/V", low="an amplifier attenuating more than 1000×",
                      high="dB typed as V/V?"),
        "noise_V_per_rtHz": Range(0.0, 1e-3, "V/√Hz", high="nV/√Hz typed as V/√Hz?"),
        "corner_Hz": Range(0.0, 1e7, "Hz"), "offset_V": Range(-10.0, 10.0, "V", high="mV typed as V?",
                                                             low="mV typed as V?"),
        "flicker_low_Hz": Range(1e-9, 1e6, "Hz"), "v_ref_V": Range(0.01, 100.0, "V"),
        "data_rate_Hz": Range(0.01, 1e9, "S/s"), "noise_bandwidth_factor": Range(1e-3, 10.0, ""),
        "temperature_K": Range(1.0, 2000.0, "K", high="°C typed as K? (300 K is room temperature)"),
    }


def validate(cfg: SensorConfig) -> None:
    """Raise InputError naming the field for a physically impossible or inconsistent config
    (every number also inside its physical range, ``_ranges``)."""
    if cfg.arrangement not in ARRANGEMENTS:
        raise InputError(f"bridge.arrangement: unknown {cfg.arrangement!r}; expected one of "
                         f"{', '.join(ARRANGEMENTS)}")
    for name in ("gauge_factor", "gauge_resistance_ohm", "excitation_V", "strain_limit", "gain",
                 "v_ref_V", "enob", "data_rate_Hz", "noise_bandwidth_factor", "temperature_K",
                 "flicker_low_Hz"):
        _num(cfg, name, positive=True)
    for name in ("lead_resistance_ohm", "noise_V_per_rtHz", "corner_Hz"):
        _num(cfg, name, nonneg=True)
    _num(cfg, "offset_V")
    _num(cfg, "rated_strain", nonneg=True)
    for name, rng in _ranges().items():
        why = rng.problem(float(getattr(cfg, name)))
        if why:
            raise InputError(f"{_field(name)}: {why}")
    nu = _num(cfg, "poisson_ratio")
    if not -1.0 < nu < 0.5:
        raise InputError(f"bridge.poisson_ratio: must lie in (−1, 0.5), got {nu}")
    if isinstance(cfg.bits, bool) or not isinstance(cfg.bits, int) or not 2 <= cfg.bits <= 32:
        raise InputError(f"adc.bits: must be an integer in 2..32, got {cfg.bits!r}")
    if cfg.range_factor not in (1, 2, 1.0, 2.0):
        raise InputError(f"adc.range_factor: must be 1 (±V_ref) or 2 (±2·V_ref), got "
                         f"{cfg.range_factor!r}")
    if cfg.enob_definition not in _adc.ENOB_DEFINITIONS:
        raise InputError(f"adc.enob_definition: must be 'ti' or 'ieee', got {cfg.enob_definition!r}")
    if cfg.enob > cfg.bits:
        raise InputError(f"adc.enob: {cfg.enob} exceeds the ADC's {cfg.bits} bits")
    if cfg.enob_data_rate_Hz is not None:
        _num(cfg, "enob_data_rate_Hz", positive=True)
    if cfg.strain_limit > 0.1:
        raise InputError(f"bridge.strain_limit: {cfg.strain_limit} is beyond any foil gauge "
                         "(typ. 0.03)")
    if cfg.rated_strain > cfg.strain_limit:
        raise InputError(f"bridge.rated_strain: {cfg.rated_strain} beyond the gauge range "
                         f"±{cfg.strain_limit}")
    if cfg.gauge_factor * cfg.rated_strain >= 1.0:
        raise InputError("bridge.rated_strain: GF·ε ≥ 1 makes a gauge resistance non-positive")
    # saturation at rated load: exact bridge output of the pattern, through the gain
    from bridge.wheatstone import ratio_from_strain
    v_rated = abs(float(ratio_from_strain(cfg.rated_strain, cfg.arrangement, cfg.gauge_factor,
                                          cfg.gauge_resistance_ohm, cfg.lead_resistance_ohm,
                                          cfg.poisson_ratio))) * cfg.excitation_V
    v_adc = cfg.gain * (v_rated + abs(cfg.offset_V))
    v_max = cfg.range_factor * cfg.v_ref_V
    if v_adc > v_max:
        raise InputError(f"amplifier.gain: rated bridge output {v_rated * 1e3:.4g} mV "
                         f"(+offset) × gain {cfg.gain:g} = {v_adc:.4g} V saturates the ADC range "
                         f"±{v_max:g} V")


def sensor_config_from_dict(data: dict, source: str = "<dict>") -> tuple[SensorConfig, float | None]:
    """(SensorConfig, strain_per_Nm or None) from a TOML-shaped dict; unknown keys are errors."""
    if not isinstance(data, dict):
        raise InputError(f"{source}: expected a table, got {type(data).__name__}")
    kwargs = {}
    strain_per_Nm = None
    for sec, table in data.items():
        if sec == "torque":
            if not isinstance(table, dict):
                raise InputError(f"{source}: [torque] must be a table")
            extra = set(table) - {"strain_per_Nm"}
            if extra:
                raise InputError(f"{source}: torque.{sorted(extra)[0]}: unknown key")
            if "strain_per_Nm" in table:
                v = table["strain_per_Nm"]
                if (isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v)
                        or v <= 0):
                    raise InputError(f"{source}: torque.strain_per_Nm: must be a number > 0, "
                                     f"got {v!r}")
                strain_per_Nm = float(v)
            continue
        if sec not in _SECTIONS:
            raise InputError(f"{source}: [{sec}]: unknown section; expected "
                             f"{', '.join(list(_SECTIONS) + ['torque'])}")
        if not isinstance(table, dict):
            raise InputError(f"{source}: [{sec}] must be a table")
        for key, value in table.items():
            if key not in _SECTIONS[sec]:
                raise InputError(f"{source}: {sec}.{key}: unknown key; expected one of "
                                 f"{', '.join(_SECTIONS[sec])}")
            if isinstance(value, int) and not isinstance(value, bool) and key != "bits":
                value = float(value)
            kwargs[key] = value
    try:
        return SensorConfig(**kwargs), strain_per_Nm
    except InputError as exc:
        raise InputError(f"{source}: {exc}") from None


def load_sensor_config(path: str | os.PathLike) -> tuple[SensorConfig, float | None]:
    """Read and validate a sensor TOML file → (SensorConfig, strain_per_Nm or None)."""
    path = Path(path)
    return sensor_config_from_dict(read_toml(path), source=str(path))
