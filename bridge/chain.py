"""Vectorized sensor chain: torque → gauge strain → bridge volts → gain → ADC counts → torque.

    ε      = strain_per_Nm · τ                       (reference-gauge strain, pattern of the bridge)
    V_br   = V_ex · ratio(ε)                          (exact bridge, ``wheatstone.ratio_from_strain``)
    V_adc  = G · (V_br + V_off + drift · t) + n,      n ~ N(0, σ²), σ² = G²(σ_J² + σ_amp²) + σ_adc²
    code   = clip(round(V_adc / LSB), −2^(N−1), 2^(N−1) − 1)   (int64; clipped = saturated)
    τ̂      = strain_from_ratio((code·LSB/G − V_off)/V_ex) / strain_per_Nm   (nominal, tared inverse)

σ_J, σ_amp and σ_adc are the budget's terms over one sample's noise bandwidth (white, so the
1/f part of the amplifier noise is folded in as white of equal variance). Saturated samples
raise an ADCSaturationWarning and their torque is NaN.

Default strain per N·m (``PAPER_STRAIN_PER_NM`` = 5.72e-4 /N·m), from the paper's calibration:
eq. 12 slope 0.0115 read as mV per gram (1000 g → 11.5 mV, matching the reported ≈ 10 mV maximum
differential output), masses hung at the end of the thigh, lever arm l_1 = 0.205 m (Table I; our
assumption — the paper does not state it; it puts 1 kg at 2.0 N·m, the 0–2 N·m range of Fig. 3),
g = 9.81 m/s²: S = 0.0115 mV/g / (9.81e-3 N/g · 0.205 m) = 5.72 mV/N·m, and for a full bending
bridge V_o = GF ε V_ex, so ε/τ = S / (GF V_ex) = 5.72e-4 per N·m.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from bridge import adc as _adc
from bridge.budget import noise_budget
from bridge.config import SensorConfig
from bridge.wheatstone import BridgeWarning, StrainRangeWarning, effective_gauge_factor, strain_from_ratio
from userio.errors import InputError


class ADCSaturationWarning(BridgeWarning):
    """Samples clipped at the ADC's rails; their torque is returned as NaN, never as a number."""


PAPER_SLOPE_mV_PER_g = 0.0115        # eq. 12
PAPER_LEVER_ARM_m = 0.205            # assumed: masses at the end of link 1 (l_1, Table I)
GRAVITY_m_per_s2 = 9.81              # the workbench's gravity (docs/conventions.md)
PAPER_SENSITIVITY_V_PER_NM = (PAPER_SLOPE_mV_PER_g * 1e-3
                              / (1e-3 * GRAVITY_m_per_s2 * PAPER_LEVER_ARM_m))
PAPER_STRAIN_PER_NM = PAPER_SENSITIVITY_V_PER_NM / (2.0 * 5.0 * 1.0)   # GF V_ex s (full bending)


def _as_rng(rng) -> np.random.Generator:
    if isinstance(rng, np.random.Generator):
        return rng
    if isinstance(rng, (int, np.integer)) and not isinstance(rng, bool):
        return np.random.default_rng(rng)
    raise InputError(f"rng: expected a numpy Generator or an integer seed, got {type(rng).__name__}")


@dataclass(frozen=True)
class SensorChain:
    """The torque sensor: a SensorConfig, a strain per N·m, an optional offset drift (V/s)."""

    config: SensorConfig = field(default_factory=SensorConfig)
    strain_per_Nm: float = PAPER_STRAIN_PER_NM
    drift_V_per_s: float = 0.0

    def __post_init__(self):
        s = self.strain_per_Nm
        if isinstance(s, bool) or not isinstance(s, (int, float)) or not math.isfinite(s) or s == 0:
            raise InputError(f"strain_per_Nm: must be a finite non-zero number, got {s!r}")
        if not math.isfinite(self.drift_V_per_s):
            raise InputError(f"drift_V_per_s: must be finite, got {self.drift_V_per_s}")

    # ---- derived constants (cached) -----------------------------------------------------
    @cached_property
    def _y_per_Nm(self) -> float:
        c = self.config
        gf = effective_gauge_factor(c.gauge_factor, c.gauge_resistance_ohm, c.lead_resistance_ohm)
        return gf * self.strain_per_Nm

    @cached_property
    def _codes_per_ratio(self) -> float:
        c = self.config
        return c.gain * c.excitation_V / c.lsb_V

    @cached_property
    def noise_rms_V(self) -> float:
        """Per-sample noise at the ADC input excluding quantization: √(G²(σ_J²+σ_amp²) + σ_adc²)."""
        b = noise_budget(self.config)
        t = b.terms_V
        return self.config.gain * math.sqrt(t["johnson"] ** 2 + t["amplifier"] ** 2 + t["adc"] ** 2)

    @cached_property
    def noise_std_Nm(self) -> float:
        """Torque-referred total noise std of one sample (incl. quantization), at small torque."""
        return noise_budget(self.config, abs(self.strain_per_Nm)).total_Nm

    @property
    def sensitivity_V_per_Nm(self) -> float:
        """Bridge output per N·m at zero torque: s GF_eff V_ex · strain_per_Nm."""
        return self.config.bridge_sensitivity_V_per_strain * self.strain_per_Nm

    @property
    def counts_per_Nm(self) -> float:
        return self.sensitivity_V_per_Nm * self.config.gain / self.config.lsb_V

    @property
    def code_limits(self) -> tuple[int, int]:
        return _adc.code_limits(self.config.bits)

    # ---- forward -------------------------------------------------------------------------
    def _ratio(self, torque_Nm) -> np.ndarray:
        """Exact V_o/V_ex of the bridge pattern at τ (closed forms of ratio_from_strain)."""
        c = self.config
        y = np.multiply(np.atleast_1d(torque_Nm), self._y_per_Nm, dtype=float)
        if y.size:
            y_lim = c.strain_limit * abs(self._y_per_Nm / self.strain_per_Nm)   # limit · GF_eff
            if y.max() > y_lim or y.min() < -y_lim:
                warnings.warn(f"gauge strain beyond ±{c.strain_limit:g} (|τ| up to "
                              f"{float(np.max(np.abs(torque_Nm))):.4g} N·m)", StrainRangeWarning,
                              stacklevel=3)
        a, nu = c.arrangement, c.poisson_ratio
        if a == "full_bending":
            return y
        if a == "half_bending":
            y *= 0.5
            return y
        if a == "full_poisson":
            y *= 0.5 * (1.0 + nu)
            return y
        if a == "quarter":
            return y / (2.0 * (2.0 + y))
        if a == "half_poisson":
            return y * (1.0 + nu) / (2.0 * (2.0 + (1.0 - nu) * y))
        return y * (1.0 + nu) / (2.0 + (1.0 - nu) * y)        # full_poisson_iii

    def strain(self, torque_Nm) -> np.ndarray:
        """Reference-gauge strain ε = strain_per_Nm · τ."""
        return np.multiply(torque_Nm, self.strain_per_Nm, dtype=float)

    def bridge_volts(self, torque_Nm) -> np.ndarray:
        """Noise-free bridge output V_ex · ratio(ε(τ)) (before gain and offset)."""
        return (self._ratio(torque_Nm) * self.config.excitation_V).reshape(np.shape(torque_Nm))

    def volts(self, torque_Nm, time_s=None) -> np.ndarray:
        """Noise-free ADC-input volts G (V_br + V_off + drift · t)."""
        c = self.config
        v = self.bridge_volts(torque_Nm) + c.offset_V
        if time_s is not None and self.drift_V_per_s:
            v = v + self.drift_V_per_s * np.asarray(time_s, dtype=float)
        return c.gain * v

    def _counts(self, torque_Nm, rng, time_s=None):
        c = self.config
        shape = np.shape(torque_Nm)
        x = self._ratio(torque_Nm)                 # a fresh float array, at least 1-d
        x *= self._codes_per_ratio
        x += c.gain * c.offset_V / c.lsb_V
        if time_s is not None and self.drift_V_per_s:
            x += (c.gain * self.drift_V_per_s / c.lsb_V) * np.asarray(time_s, dtype=float)
        sigma_counts = self.noise_rms_V / c.lsb_V
        if sigma_counts > 0:
            noise = _as_rng(rng).standard_normal(x.shape)
            noise *= sigma_counts
            x += noise
        np.rint(x, out=x)
        lo, hi = self.code_limits
        n_sat = 0
        if x.size and (x.min() < lo or x.max() > hi):
            n_sat = int(np.count_nonzero((x < lo) | (x > hi)))
            np.clip(x, lo, hi, out=x)
        return x.astype(np.int64).reshape(shape), n_sat

    def counts(self, torque_Nm, rng, time_s=None) -> np.ndarray:
        """Noisy, quantized, saturated ADC codes (int64), shape of ``torque_Nm``.

        ``rng``: a numpy Generator (or an int seed). Saturated samples warn (ADCSaturationWarning)
        and sit at the rail codes, which :meth:`torque_from_counts` maps to NaN.
        """
        codes, n_sat = self._counts(torque_Nm, rng, time_s)
        if n_sat:
            warnings.warn(f"{n_sat} of {codes.size} samples saturate the ADC "
                          f"(±{self.config.range_factor * self.config.v_ref_V:g} V)",
                          ADCSaturationWarning, stacklevel=2)
        return codes

    # ---- inverse -------------------------------------------------------------------------
    def bridge_volts_from_counts(self, counts) -> np.ndarray:
        """Bridge output implied by codes, tared: code · LSB / G − V_off (rail codes → NaN)."""
        c = self.config
        codes = np.atleast_1d(np.asarray(counts))
        if codes.dtype.kind not in "iuf":
            raise InputError(f"counts: expected integer ADC codes, got dtype {codes.dtype}")
        v = codes * (c.lsb_V / c.gain)
        v -= c.offset_V
        lo, hi = self.code_limits
        if codes.size and (codes.min() <= lo or codes.max() >= hi):
            rail = (codes <= lo) | (codes >= hi)
            warnings.warn(f"{int(np.count_nonzero(rail))} sample(s) at the ADC rails "
                          "(saturated): torque set to NaN", ADCSaturationWarning, stacklevel=3)
            v[rail] = np.nan
        return v.reshape(np.shape(counts))

    def torque_from_counts(self, counts) -> np.ndarray:
        """Nominal inverse τ̂ = strain_from_ratio(V_br/V_ex) / strain_per_Nm; saturated → NaN."""
        c = self.config
        ratio = np.asarray(self.bridge_volts_from_counts(counts), dtype=float)
        ratio /= c.excitation_V
        if c.arrangement in ("full_bending", "half_bending", "full_poisson"):
            # exactly linear patterns: V/V_ex = s · y
            s = {"full_bending": 1.0, "half_bending": 0.5,
                 "full_poisson": 0.5 * (1.0 + c.poisson_ratio)}[c.arrangement]
            ratio *= 1.0 / (s * self._y_per_Nm)
            return ratio
        eps = strain_from_ratio(ratio, c.arrangement, c.gauge_factor, c.gauge_resistance_ohm,
                                c.lead_resistance_ohm, c.poisson_ratio)
        return eps / self.strain_per_Nm

    def measure(self, torque_Nm, rng, time_s=None) -> np.ndarray:
        """torque_from_counts(counts(τ, rng)): the sensor's torque reading (N·m)."""
        codes, n_sat = self._counts(torque_Nm, rng, time_s)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", ADCSaturationWarning)
            out = self.torque_from_counts(codes)
        if n_sat:
            warnings.warn(f"{n_sat} of {codes.size} samples saturate the ADC: torque NaN",
                          ADCSaturationWarning, stacklevel=2)
        return out


_CHAIN_FIELDS = ("drift_V_per_s",)


def paper_chain(strain_per_Nm: float | None = None, **overrides) -> SensorChain:
    """The paper's sensor (SensorConfig defaults) with ``PAPER_STRAIN_PER_NM`` unless given.

    ``overrides``: SensorConfig fields (e.g. ``gain=100``, ``arrangement="quarter"``) and
    ``drift_V_per_s``.
    """
    chain_kw = {k: overrides.pop(k) for k in _CHAIN_FIELDS if k in overrides}
    cfg = SensorConfig().replace(**overrides) if overrides else SensorConfig()
    spn = PAPER_STRAIN_PER_NM if strain_per_Nm is None else strain_per_Nm
    return SensorChain(cfg, spn, **chain_kw)
