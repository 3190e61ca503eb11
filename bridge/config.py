"""Sensor configuration (bridge + amplifier + ADC), from TOML or a dict, validated.

TOML layout (every key optional; defaults are the paper's sensor, ``sensors/paper_sensor.toml``)::

    [bridge]      arrangement, gauge_factor, gauge_resistance_ohm, lead_resistance_ohm,
                  excitation_V, poisson_ratio, strain_limit, rated_strain
    [amplifier]   gain, noise_V_per_rtHz, corner_Hz, offset_V, flicker_low_Hz
    [adc]         bits, v_ref_V, range_factor (1: ±V_ref, 2: ±2 V_ref), enob, enob_definition
                  ("ti" | "ieee"), enob_data_rate_Hz, data_rate_Hz, noise_bandwidth_factor
    [environment] temperature_K
    [torque]      strain_per_Nm   (gauge strain ε per N·m; optional)

Validated by its schema (userio.schema.sensor): bad values raise InputError naming
``file: section.key``.
"""

from __future__ import annotations

import dataclasses
import math
import os
from dataclasses import dataclass, fields
from pathlib import Path

from bridge import adc as _adc
from userio.errors import InputError
from userio.files import read_toml
from bridge.wheatstone import effective_gauge_factor, sensitivity_factor


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


def tables(cfg: SensorConfig) -> dict:
    """The config as a sensor file's tables (userio.schema.sensor.SensorFile)."""
    out = {sec: {k: getattr(cfg, k) for k in keys} for sec, keys in _SECTIONS.items()}
    if cfg.enob_data_rate_Hz is None:
        del out["adc"]["enob_data_rate_Hz"]
    return out


def validate(cfg: SensorConfig) -> None:
    """InputError naming the field (``section.key``) for a config the sensor schema refuses
    (userio.schema.sensor: types, physical ranges, ENOB ≤ bits, no saturation at rated load)."""
    from pydantic import ValidationError

    from userio.schema.base import message
    from userio.schema.sensor import SensorFile

    try:
        SensorFile.model_validate(tables(cfg))
    except ValidationError as exc:
        raise InputError(message(exc)) from None


def sensor_config_from_dict(data: dict, source: str = "<dict>") -> tuple[SensorConfig, float | None]:
    """(SensorConfig, strain_per_Nm or None) from a sensor file's tables, validated by its
    schema (userio.schema.sensor.SensorFile); InputError naming ``source`` and the field."""
    from userio.schema import parse
    from userio.schema.sensor import SensorFile

    file = parse(SensorFile, data, source)
    kwargs = {k: getattr(getattr(file, sec), k) for sec, keys in _SECTIONS.items() for k in keys}
    return SensorConfig(**kwargs), file.torque.strain_per_Nm


def load_sensor_config(path: str | os.PathLike) -> tuple[SensorConfig, float | None]:
    """Read and validate a sensor TOML file → (SensorConfig, strain_per_Nm or None)."""
    path = Path(path)
    return sensor_config_from_dict(read_toml(path), source=str(path))
