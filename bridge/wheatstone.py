"""Wheatstone bridge: exact and linearized outputs, their inverses, self-heating.

Arm convention (all arrangements)::

    V_o / V_ex = R1/(R1 + R2) − R4/(R3 + R4)
               = (r1 r3 − r2 r4) / ((r1 + r2)(r3 + r4)),      r_i = R_i / R_0

With R_i = R (1 + GF ε_i) + R_lead this linearizes to (GF_eff/4)(ε1 − ε2 + ε3 − ε4), with the
lead-wire desensitization GF_eff = GF · R/(R + R_lead). Arms without a gauge are completion
resistors equal to the gauges' unstrained arm resistance R + R_lead (a balanced bridge), so the
output is 0 at zero strain. The numerator is evaluated as (y1 − y2 + y3 − y4) + (y1 y3 − y2 y4),
y_i = GF_eff ε_i, so there is no cancellation at small strain (1e-9 round-trips to 1e-15).

Arrangements (``strains[..., j]`` is the strain of the j-th listed gauge; "pattern" is the strain
of each gauge when the arrangement is used as intended, ε = the reference gauge's strain):

=====================  ==  ===========================  ==========================  ==============
arrangement            k   arms with gauges             pattern                      linear V_o/V_ex
=====================  ==  ===========================  ==========================  ==============
quarter                1   arm 1                        (ε)                          GF ε / 4
half_bending           2   arms 1, 2                    (ε, −ε) top/bottom           GF ε / 2
half_poisson           2   arms 1 (axial), 2 (transv.)  (ε, −ν ε)                    GF ε (1+ν)/4
full_bending           4   arms 1, 2, 3, 4              (ε, −ε, ε, −ε)               GF ε
full_poisson (II)      4   1,2 axial; 3,4 transverse    (ε, −ε, ν ε, −ν ε)           GF ε (1+ν)/2
full_poisson_iii (III) 4   1,3 axial; 2,4 transverse    (ε, −ν ε, ε, −ν ε)           GF ε (1+ν)/2
=====================  ==  ===========================  ==========================  ==============

A torque disc with ±45° shear gauges is ``full_bending`` (two gauges at +45° in arms 1, 3 see
+ε, two at −45° in arms 2, 4 see −ε). Half and full bending/Type II bridges are exactly linear in
ε for their pattern; quarter, half-Poisson and Type III are not.
"""

from __future__ import annotations

import warnings

import numpy as np

from userio.errors import InputError


class BridgeWarning(UserWarning):
    """Base class of the bridge package's warnings (filter them with this class)."""


class StrainRangeWarning(BridgeWarning):
    """A gauge strain beyond the gauge's rated range (±3 % by default): results are extrapolated."""


class BridgeInverseWarning(BridgeWarning):
    """A bridge ratio outside the arrangement's physical range (inverse singular): NaN returned."""


#: arrangement → (number of gauges k, arm index (0..3) of each gauge)
ARRANGEMENTS: dict[str, tuple[int, tuple[int, ...]]] = {
    "quarter": (1, (0,)),
    "half_bending": (2, (0, 1)),
    "half_poisson": (2, (0, 1)),
    "full_bending": (4, (0, 1, 2, 3)),
    "full_poisson": (4, (0, 1, 2, 3)),
    "full_poisson_iii": (4, (0, 1, 2, 3)),
}

DEFAULT_STRAIN_LIMIT = 0.03       # ±3 %: a typical foil-gauge strain limit
DEFAULT_POISSON_RATIO = 0.33      # 6061 aluminium


def _check_arrangement(arrangement: str) -> tuple[int, tuple[int, ...]]:
    try:
        return ARRANGEMENTS[arrangement]
    except KeyError:
        raise InputError(f"arrangement: unknown {arrangement!r}; expected one of "
                         f"{', '.join(ARRANGEMENTS)}") from None


def _check_positive(name: str, value: float) -> float:
    value = float(value)
    if not np.isfinite(value) or value <= 0:
        raise InputError(f"{name}: must be a finite number > 0, got {value}")
    return value


def effective_gauge_factor(gauge_factor: float = 2.0, gauge_resistance_ohm: float = 1000.0,
                           lead_resistance_ohm: float = 0.0) -> float:
    """GF_eff = GF · R / (R + R_lead): lead-wire desensitization (R_lead = series lead per arm)."""
    gf = _check_positive("gauge_factor", gauge_factor)
    r = _check_positive("gauge_resistance_ohm", gauge_resistance_ohm)
    r_lead = float(lead_resistance_ohm)
    if not np.isfinite(r_lead) or r_lead < 0:
        raise InputError(f"lead_resistance_ohm: must be finite and >= 0, got {r_lead}")
    return gf * r / (r + r_lead)


def pattern(arrangement: str, poisson_ratio: float = DEFAULT_POISSON_RATIO) -> np.ndarray:
    """Gauge strains per unit reference strain ε for the arrangement's intended use (table above)."""
    nu = float(poisson_ratio)
    table = {
        "quarter": [1.0],
        "half_bending": [1.0, -1.0],
        "half_poisson": [1.0, -nu],
        "full_bending": [1.0, -1.0, 1.0, -1.0],
        "full_poisson": [1.0, -1.0, nu, -nu],
        "full_poisson_iii": [1.0, -nu, 1.0, -nu],
    }
    _check_arrangement(arrangement)
    return np.array(table[arrangement])


def sensitivity_factor(arrangement: str, poisson_ratio: float = DEFAULT_POISSON_RATIO) -> float:
    """Linear slope s with V_o/V_ex ≈ s · GF_eff · ε for the pattern: 1/4 quarter … 1 full bending."""
    p = np.zeros(4)
    _, arms = _check_arrangement(arrangement)
    p[list(arms)] = pattern(arrangement, poisson_ratio)
    return float((p[0] - p[1] + p[2] - p[3]) / 4.0)


def gauge_strains(strain, arrangement: str = "full_bending",
                  poisson_ratio: float = DEFAULT_POISSON_RATIO) -> np.ndarray:
    """Gauge strains (..., k) = ε[..., None] · pattern: the gauges of the arrangement at strain ε."""
    return np.asarray(strain, dtype=float)[..., None] * pattern(arrangement, poisson_ratio)


def _arm_y(strains, arrangement, gf_eff, strain_limit):
    k, arms = _check_arrangement(arrangement)
    eps = np.asarray(strains, dtype=float)
    if eps.ndim == 0 or eps.shape[-1] != k:
        raise InputError(f"strains: arrangement {arrangement!r} needs shape (..., {k}), "
                         f"got {eps.shape}")
    if eps.size:
        peak = float(np.max(np.abs(eps)))
        if not np.isfinite(peak):
            raise InputError("strains: contains NaN or inf")
        if np.any(eps * gf_eff <= -1.0):
            raise InputError(f"strains: a gauge strain ≤ −1/GF gives a non-positive resistance "
                             f"(min strain {float(eps.min()):.3g})")
        if strain_limit is not None and peak > strain_limit:
            warnings.warn(f"gauge strain {peak:.3g} beyond the gauge range ±{strain_limit:g}",
                          StrainRangeWarning, stacklevel=3)
    y = [0.0, 0.0, 0.0, 0.0]
    for j, arm in enumerate(arms):
        y[arm] = gf_eff * eps[..., j]
    return y


def output_ratio(strains, arrangement: str = "full_bending", gauge_factor: float = 2.0,
                 gauge_resistance_ohm: float = 1000.0, lead_resistance_ohm: float = 0.0,
                 strain_limit: float | None = DEFAULT_STRAIN_LIMIT) -> np.ndarray:
    """Exact V_o/V_ex = (y1 − y2 + y3 − y4 + y1 y3 − y2 y4) / ((2 + y1 + y2)(2 + y3 + y4)).

    y_i = GF_eff ε_i (0 for completion arms); ``strains`` has shape (..., k), gauges in the arm
    order of the module table. Strains beyond ±``strain_limit`` warn (StrainRangeWarning).
    """
    gf_eff = effective_gauge_factor(gauge_factor, gauge_resistance_ohm, lead_resistance_ohm)
    y1, y2, y3, y4 = _arm_y(strains, arrangement, gf_eff, strain_limit)
    num = (y1 - y2 + y3 - y4) + (y1 * y3 - y2 * y4)
    den = (2.0 + y1 + y2) * (2.0 + y3 + y4)
    return np.asarray(num / den, dtype=float)


def linear_output_ratio(strains, arrangement: str = "full_bending", gauge_factor: float = 2.0,
                        gauge_resistance_ohm: float = 1000.0, lead_resistance_ohm: float = 0.0,
                        strain_limit: float | None = DEFAULT_STRAIN_LIMIT) -> np.ndarray:
    """Linearized V_o/V_ex = (GF_eff/4)(ε1 − ε2 + ε3 − ε4) (paper eq. 10 for the quarter bridge)."""
    gf_eff = effective_gauge_factor(gauge_factor, gauge_resistance_ohm, lead_resistance_ohm)
    y1, y2, y3, y4 = _arm_y(strains, arrangement, gf_eff, strain_limit)
    return np.asarray((y1 - y2 + y3 - y4) / 4.0, dtype=float)


def ratio_from_strain(strain, arrangement: str = "full_bending", gauge_factor: float = 2.0,
                      gauge_resistance_ohm: float = 1000.0, lead_resistance_ohm: float = 0.0,
                      poisson_ratio: float = DEFAULT_POISSON_RATIO) -> np.ndarray:
    """Exact V_o/V_ex of the arrangement's pattern at reference strain ε (closed forms, y = GF_eff ε).

    quarter y/(2(2+y)); half_bending y/2; half_poisson y(1+ν)/(2(2+(1−ν)y)); full_bending y;
    full_poisson y(1+ν)/2; full_poisson_iii y(1+ν)/(2+(1−ν)y). No range checks (hot path).
    """
    gf_eff = effective_gauge_factor(gauge_factor, gauge_resistance_ohm, lead_resistance_ohm)
    _check_arrangement(arrangement)
    y = gf_eff * np.asarray(strain, dtype=float)
    nu = float(poisson_ratio)
    if arrangement == "quarter":
        return y / (2.0 * (2.0 + y))
    if arrangement == "half_bending":
        return 0.5 * y
    if arrangement == "half_poisson":
        return y * (1.0 + nu) / (2.0 * (2.0 + (1.0 - nu) * y))
    if arrangement == "full_bending":
        return y
    if arrangement == "full_poisson":
        return 0.5 * (1.0 + nu) * y
    return y * (1.0 + nu) / (2.0 + (1.0 - nu) * y)          # full_poisson_iii


def strain_from_ratio(ratio, arrangement: str = "full_bending", gauge_factor: float = 2.0,
                      gauge_resistance_ohm: float = 1000.0, lead_resistance_ohm: float = 0.0,
                      poisson_ratio: float = DEFAULT_POISSON_RATIO) -> np.ndarray:
    """Exact inverse of :func:`ratio_from_strain`: reference strain ε from V_o/V_ex = v.

    y = GF_eff ε: quarter 4v/(1 − 2v); half_bending 2v; half_poisson 4v/((1+ν) − 2v(1−ν));
    full_bending v; full_poisson 2v/(1+ν); full_poisson_iii 2v/((1+ν) − v(1−ν)).
    Ratios outside the physical range (an arm resistance ≤ 0 or the pole of the inverse, e.g.
    v ≥ 1/2 for the quarter bridge) give NaN with a BridgeInverseWarning.
    """
    gf_eff = effective_gauge_factor(gauge_factor, gauge_resistance_ohm, lead_resistance_ohm)
    _check_arrangement(arrangement)
    v = np.asarray(ratio, dtype=float)
    nu = float(poisson_ratio)
    with np.errstate(divide="ignore", invalid="ignore"):
        if arrangement == "quarter":
            den = 1.0 - 2.0 * v
            y = 4.0 * v / den
        elif arrangement == "half_bending":
            den = np.ones_like(v)
            y = 2.0 * v
        elif arrangement == "half_poisson":
            den = (1.0 + nu) - 2.0 * v * (1.0 - nu)
            y = 4.0 * v / den
        elif arrangement == "full_bending":
            den = np.ones_like(v)
            y = v.copy()
        elif arrangement == "full_poisson":
            den = np.ones_like(v)
            y = 2.0 * v / (1.0 + nu)
        else:
            den = (1.0 + nu) - v * (1.0 - nu)
            y = 2.0 * v / den
        p = pattern(arrangement, nu)
        # every arm resistance r = 1 + p_j y must stay > 0, and the inverse's denominator > 0
        r_min = np.minimum(1.0 + p.max() * y, 1.0 + p.min() * y)
        bad = ~(np.isfinite(y) & (den > 0) & (r_min > 0))
    if np.any(bad):
        warnings.warn(f"{int(np.count_nonzero(bad))} bridge ratio(s) outside the physical range "
                      f"of a {arrangement} bridge: strain set to NaN", BridgeInverseWarning,
                      stacklevel=2)
        y = np.where(bad, np.nan, y)
    return y / gf_eff


def output_resistance_ohm(gauge_resistance_ohm: float = 1000.0,
                          lead_resistance_ohm: float = 0.0) -> float:
    """Thevenin output resistance of a balanced bridge: 2 · (R/2) = R (+ leads), for Johnson noise."""
    return _check_positive("gauge_resistance_ohm", gauge_resistance_ohm) + float(lead_resistance_ohm)


def self_heating_W(excitation_V: float = 5.0, gauge_resistance_ohm: float = 1000.0) -> float:
    """Power dissipated in each gauge of a balanced bridge: P = (V_ex/2)² / R."""
    v = _check_positive("excitation_V", excitation_V)
    return (v / 2.0) ** 2 / _check_positive("gauge_resistance_ohm", gauge_resistance_ohm)
