"""A sensor file (``sensors/paper_sensor.toml``): bridge → amplifier → ADC, and strain per N·m.

Every key is optional; the defaults are the paper's sensor (bridge.config.SensorConfig).
"""

from __future__ import annotations

from typing import Literal, Optional

from pydantic import field_validator, model_validator

from bridge.wheatstone import ARRANGEMENTS
from userio.schema.base import Field, Model, Range, fail, integer, num


class BridgeTable(Model):
    """``[bridge]``: the Wheatstone bridge of foil gauges."""

    arrangement: Literal[tuple(ARRANGEMENTS)] = Field(
        "full_bending", description="gauge pattern (full_bending: ±45° shear gauges ε, −ε, ε, −ε "
        "in arms 1..4)")
    gauge_factor: num(Range(0.1, 1000.0, ""), gt=0) = Field(2.0, description="GF")
    gauge_resistance_ohm: num(Range(1.0, 1e7, "Ω", high="mΩ typed as Ω?"), gt=0) = Field(
        1000.0, description="nominal gauge resistance")
    lead_resistance_ohm: num(Range(0.0, 1e4, "Ω"), ge=0) = Field(
        0.0, description="series lead resistance per arm (desensitizes GF)")
    excitation_V: num(Range(1e-3, 100.0, "V", high="mV typed as V?"), gt=0) = Field(
        5.0, description="bridge excitation")
    poisson_ratio: num(gt=-1.0, lt=0.5) = Field(0.33, description="ν of the flexure (the "
                                                "*_poisson arrangements)")
    strain_limit: num(gt=0, le=0.1) = Field(0.03, description="gauge range ±ε (a foil gauge: "
                                            "typ. 0.03)")
    rated_strain: num(ge=0) = Field(1e-3, description="strain at rated load (saturation check)")


class AmplifierTable(Model):
    """``[amplifier]``: gain 1 and zero noise is no amplifier (the bridge straight into the ADC)."""

    gain: num(Range(1e-3, 1e6, "V/V", low="an amplifier attenuating more than 1000×",
                    high="dB typed as V/V?"), gt=0) = Field(1.0, description="voltage gain")
    noise_V_per_rtHz: num(Range(0.0, 1e-3, "V/√Hz", high="nV/√Hz typed as V/√Hz?"), ge=0) = Field(
        0.0, description="input-referred white voltage noise density")
    corner_Hz: num(Range(0.0, 1e7, "Hz"), ge=0) = Field(0.0, description="1/f corner frequency")
    offset_V: num(Range(-10.0, 10.0, "V", high="mV typed as V?", low="mV typed as V?")) = Field(
        0.0, description="input-referred offset")
    flicker_low_Hz: num(Range(1e-9, 1e6, "Hz"), gt=0) = Field(
        0.1, description="lower integration limit of 1/f noise (1/observation time)")


class AdcTable(Model):
    """``[adc]``: the converter."""

    bits: integer(ge=2, le=32) = Field(24, description="output word width")
    v_ref_V: num(Range(0.01, 100.0, "V"), gt=0) = Field(2.5, description="reference voltage")
    range_factor: num() = Field(1.0, description="input range: 1 = ±V_ref, 2 = ±2·V_ref")
    enob: num(gt=0) = Field(16.0, description="effective number of bits (≤ bits)")
    enob_definition: Literal["ti", "ieee"] = Field(
        "ti", description="ti: log2(FSR/σ); ieee: (SINAD − 1.76)/6.02 ≈ ti − 1.79")
    enob_data_rate_Hz: Optional[num(gt=0)] = Field(
        None, description="data rate at which ENOB holds (default: data_rate_Hz)")
    data_rate_Hz: num(Range(0.01, 1e9, "S/s"), gt=0) = Field(4000.0, description="output data rate")
    noise_bandwidth_factor: num(Range(1e-3, 10.0, ""), gt=0) = Field(
        0.5, description="ENBW of one sample = factor × data rate")

    @field_validator("range_factor")
    @classmethod
    def _range(cls, v):
        if v not in (1.0, 2.0):
            raise ValueError(f"must be 1 (±V_ref) or 2 (±2·V_ref), got {v!r}")
        return v

    @model_validator(mode="after")
    def _enob(self):
        if self.enob > self.bits:
            raise fail("enob", f"{self.enob} exceeds the ADC's {self.bits} bits")
        return self


class EnvironmentTable(Model):
    """``[environment]``."""

    temperature_K: num(Range(1.0, 2000.0, "K", high="°C typed as K? (300 K is room temperature)"),
                       gt=0) = Field(300.0, description="temperature (Johnson noise)")


class TorqueTable(Model):
    """``[torque]``: how the sensor's flexure turns torque into gauge strain."""

    strain_per_Nm: Optional[num(gt=0)] = Field(
        None, description="reference-gauge strain ε per N·m of joint torque")


class SensorFile(Model):
    """A strain-gauge sensor: bridge → (amplifier) → ADC (``--config``, a scene's ``[sensor] file``)."""

    bridge: BridgeTable = Field(BridgeTable(), description="the bridge")
    amplifier: AmplifierTable = Field(AmplifierTable(), description="the amplifier")
    adc: AdcTable = Field(AdcTable(), description="the converter")
    environment: EnvironmentTable = Field(EnvironmentTable(), description="the environment")
    torque: TorqueTable = Field(TorqueTable(), description="torque → strain")

    @model_validator(mode="after")
    def _consistent(self):
        b, a, adc = self.bridge, self.amplifier, self.adc
        if b.rated_strain > b.strain_limit:
            raise fail("bridge.rated_strain", f"{b.rated_strain} beyond the gauge range "
                       f"±{b.strain_limit}")
        if b.gauge_factor * b.rated_strain >= 1.0:
            raise fail("bridge.rated_strain", "GF·ε ≥ 1 makes a gauge resistance non-positive")
        # saturation at rated load: exact bridge output of the pattern, through the gain
        from bridge.wheatstone import ratio_from_strain

        v_rated = abs(float(ratio_from_strain(b.rated_strain, b.arrangement, b.gauge_factor,
                                              b.gauge_resistance_ohm, b.lead_resistance_ohm,
                                              b.poisson_ratio))) * b.excitation_V
        v_adc = a.gain * (v_rated + abs(a.offset_V))
        v_max = adc.range_factor * adc.v_ref_V
        if v_adc > v_max:
            raise fail("amplifier.gain", f"rated bridge output {v_rated * 1e3:.4g} mV (+offset) × "
                       f"gain {a.gain:g} = {v_adc:.4g} V saturates the ADC range ±{v_max:g} V")
        return self
