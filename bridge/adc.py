"""ADC model: full-scale range, LSB, ENOB ↔ noise, noise-free bits, quantization.

Conventions:
- Bipolar input range ±k·V_ref (k = ``range_factor`` 1 or 2 on the ADS127L21), so the full-scale
  range is FSR = 2 k V_ref and the LSB is FSR / 2^N; codes run from −2^(N−1) to 2^(N−1) − 1.
  (Paper eq. 11 counts the resolution as V_ref / 2^N, half our LSB for k = 1; see
  ``bridge.budget.min_detectable_strain``.)
- ENOB definitions (a parameter, ``"ti"`` or ``"ieee"``):
  * "ti"   (TI "effective resolution"):  ENOB_ti = log2(FSR / σ_n)
  * "ieee" (sine-wave ENOB):             ENOB_ieee = (SINAD − 1.76)/6.02, SINAD of a full-scale
    sine of rms FSR/(2√2): SINAD = 20 log10(FSR / (2√2 σ_n)).
  Hence ENOB_ieee = (20 log10(2) · ENOB_ti − 20 log10(2√2) − 1.76)/6.02
                  ≈ ENOB_ti − 1.79 bits.
- σ_n from ENOB is the ADC's total input-referred noise (thermal + quantization) at the data
  rate where ENOB was specified.
- Noise-free bits = log2(FSR / (6.6 σ_n)) (peak-to-peak ≈ 6.6 σ).
"""

from __future__ import annotations

import math

import numpy as np

from userio.errors import InputError

ENOB_DEFINITIONS = ("ti", "ieee")
_DB_PER_BIT = 20.0 * math.log10(2.0)         # 6.0206 dB
_SINE_CREST_DB = 20.0 * math.log10(2.0 * math.sqrt(2.0))   # 9.0309 dB


def full_scale_range_V(v_ref_V: float, range_factor: float = 1.0) -> float:
    """FSR = 2 · k · V_ref (input range ±k V_ref)."""
    return 2.0 * float(range_factor) * float(v_ref_V)


def lsb_V(bits: int, v_ref_V: float, range_factor: float = 1.0) -> float:
    """LSB = FSR / 2^N."""
    return full_scale_range_V(v_ref_V, range_factor) / 2.0 ** int(bits)


def noise_rms_from_enob(enob: float, fsr_V: float, definition: str = "ti") -> float:
    """Input-referred rms noise σ_n: FSR/2^ENOB ("ti"), FSR/(2√2)·10^(−(6.02 ENOB + 1.76)/20) ("ieee")."""
    if definition == "ti":
        return float(fsr_V) / 2.0 ** float(enob)
    if definition == "ieee":
        sinad_dB = 6.02 * float(enob) + 1.76
        return float(fsr_V) / (2.0 * math.sqrt(2.0)) * 10.0 ** (-sinad_dB / 20.0)
    raise InputError(f"enob_definition: {definition!r} is not one of {', '.join(ENOB_DEFINITIONS)}")


def enob_from_noise_rms(noise_rms_V: float, fsr_V: float, definition: str = "ti") -> float:
    """Inverse of :func:`noise_rms_from_enob`."""
    if definition == "ti":
        return math.log2(float(fsr_V) / float(noise_rms_V))
    if definition == "ieee":
        sinad_dB = 20.0 * math.log10(float(fsr_V) / (2.0 * math.sqrt(2.0) * float(noise_rms_V)))
        return (sinad_dB - 1.76) / 6.02
    raise InputError(f"enob_definition: {definition!r} is not one of {', '.join(ENOB_DEFINITIONS)}")


def convert_enob(enob: float, from_definition: str, to_definition: str) -> float:
    """Convert an ENOB between definitions at equal noise (ti → ieee subtracts ≈ 1.79 bits)."""
    sigma = noise_rms_from_enob(enob, 1.0, from_definition)
    return enob_from_noise_rms(sigma, 1.0, to_definition)


def noise_free_bits(noise_rms_V: float, fsr_V: float) -> float:
    """log2(FSR / (6.6 σ_n))."""
    return math.log2(float(fsr_V) / (6.6 * float(noise_rms_V)))


def quantization_noise_rms_V(lsb: float) -> float:
    """σ_q = LSB/√12 (uniform quantization error)."""
    return float(lsb) / math.sqrt(12.0)


def code_limits(bits: int) -> tuple[int, int]:
    """(min, max) two's-complement code: (−2^(N−1), 2^(N−1) − 1)."""
    return -(1 << (int(bits) - 1)), (1 << (int(bits) - 1)) - 1


def quantize(volts, bits: int, v_ref_V: float, range_factor: float = 1.0):
    """Codes = clip(round(V/LSB)) as int64, and the boolean mask of saturated samples."""
    lo, hi = code_limits(bits)
    x = np.rint(np.asarray(volts, dtype=float) / lsb_V(bits, v_ref_V, range_factor))
    saturated = (x < lo) | (x > hi)
    np.clip(x, lo, hi, out=x)
    return x.astype(np.int64), saturated
