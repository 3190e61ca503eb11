"""The calibrated sensor model: reading → applied mass → torque, with uncertainty.

Forward model f(m; θ) = slope·m + offset + quad·m² + hysteresis·w (w = 1 on the unloading
branch, 0 loading, ½ if the branch is unknown). The inverse m(r) solves f(m) = r:
    m = 2(r − b')/(a + sgn(a)·√(a² + 4c(r − b')))   (b' = offset + hysteresis·w; c = 0 → (r − b')/a)
and torque τ = m·10⁻³·g·L. Uncertainty (first order, implicit differentiation):
    ∂m/∂θ = −[m, 1, m², w]/f'(m),  Var m = gᵀ Σ g + σ²/f'(m)² [+ hysteresis²/4 if branch unknown]
with Σ the posterior covariance of the coefficients and σ the reading noise (posterior mean).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from userio.errors import InputError
from calibration.session import G_STANDARD_M_PER_S2


RANGE_MARGIN = 0.10                   # readings up to 10 % of the calibrated span outside it are used


def adc_rails(bits: int | None = None) -> tuple[int, int]:
    """(min, max) count of the converter: ``bits`` (the sensor's [adc] bits), else the width of the
    default sensor (bridge.config.SensorConfig, the one place it is written)."""
    from bridge.adc import code_limits
    from bridge.config import SensorConfig

    return code_limits(SensorConfig.bits if bits is None else bits)


@dataclass
class SensorModel:
    """A stored calibration usable downstream (estimator, Monte Carlo)."""

    model: str
    coef_names: tuple
    coef_mean: np.ndarray            # posterior mean of the coefficients
    coef_cov: np.ndarray             # posterior covariance of the coefficients
    sigma: float                     # reading noise σ (posterior mean), reading units
    samples: np.ndarray              # thinned posterior draws (S, p) of the coefficients
    sigma_samples: np.ndarray        # (S,) σ of each draw
    lever_arm_m: float | None
    reading_unit: str = "mV"
    sensor_id: str = "sensor"
    source: str = "<memory>"
    info: dict = field(default_factory=dict)
    mass_range_g: tuple | None = None     # (min, max) applied mass of the calibration session
    adc_bits: int | None = None           # the converter's width (None: the default sensor's)

    def flags(self, reading, direction=None) -> np.ndarray:
        """Per reading: "" (usable), "saturated_adc" (a count at or past the ADC's full scale,
        reading_unit "counts"), "outside_calibrated_range" (mass more than RANGE_MARGIN of the
        calibrated span outside it: extrapolation), or "no_solution" (model has no root)."""
        r = np.asarray(reading, float)
        out = np.full(r.shape, "", dtype=object)
        m = self.mass_g(r, direction)
        out[~np.isfinite(m)] = "no_solution"
        if self.mass_range_g is not None:
            lo, hi = self.mass_range_g
            pad = RANGE_MARGIN * (hi - lo)
            with np.errstate(invalid="ignore"):
                out[(m < lo - pad) | (m > hi + pad)] = "outside_calibrated_range"
        if self.reading_unit == "counts":
            lo, hi = adc_rails(self.adc_bits)
            out[(r <= lo) | (r >= hi)] = "saturated_adc"
        return out.astype(str)

    # -- coefficient bookkeeping -------------------------------------------------------------
    def _split(self, coefs):
        coefs = np.asarray(coefs, float)
        a, b = coefs[..., 0], coefs[..., 1]
        c = coefs[..., 2] if self.model == "quadratic" else np.zeros_like(a)
        h = coefs[..., 2] if self.model == "hysteresis" else np.zeros_like(a)
        return a, b, c, h

    def _weight(self, direction):
        if direction is None:
            return 0.5 if self.model == "hysteresis" else 0.0
        d = np.asarray(direction)
        if not np.all(np.isin(d, ["load", "unload"])):
            raise InputError("direction: must be 'load' or 'unload'")
        return (d == "unload").astype(float)

    def _torque_per_g(self) -> float:
        if self.lever_arm_m is None:
            raise InputError(f"{self.source}: calibration has no lever_arm_m; torque is undefined "
                             "(use mass_g(), or recalibrate with --lever-arm-m)")
        return 1e-3 * G_STANDARD_M_PER_S2 * self.lever_arm_m

    @staticmethod
    def _invert(r, a, b, c):
        """Root of c m² + a m + b − r = 0 nearest the linear one (NaN if none)."""
        d = r - b
        with np.errstate(invalid="ignore", divide="ignore"):
            disc = a * a + 4 * c * d
            m = 2 * d / (a + np.sign(a) * np.sqrt(disc))
        return np.where(disc >= 0, m, np.nan)

    # -- public API --------------------------------------------------------------------------
    def mass_g(self, reading, direction=None) -> np.ndarray:
        """Applied mass (g) that produces ``reading`` (posterior-mean coefficients)."""
        a, b, c, h = self._split(self.coef_mean)
        return self._invert(np.asarray(reading, float), a, b + h * self._weight(direction), c)

    def mass_std_g(self, reading, direction=None, include_noise: bool = True) -> np.ndarray:
        """Standard uncertainty of :meth:`mass_g` (coefficients + reading noise, first order)."""
        r = np.asarray(reading, float)
        w = self._weight(direction)
        m = self.mass_g(r, direction)
        a, b, c, h = self._split(self.coef_mean)
        fprime = a + 2 * c * m
        cols = [m, np.ones_like(m)]
        if self.model == "quadratic":
            cols.append(m * m)
        elif self.model == "hysteresis":
            cols.append(np.broadcast_to(w, m.shape).astype(float))
        g = -np.stack(cols, axis=-1) / fprime[..., None]
        var = np.einsum("...i,ij,...j->...", g, self.coef_cov, g)
        if include_noise:
            var = var + (self.sigma / fprime) ** 2
        if self.model == "hysteresis" and direction is None:
            var = var + (h / fprime) ** 2 / 4
        return np.sqrt(var)

    def torque(self, reading, direction=None) -> np.ndarray:
        """Torque (N·m) τ = m(reading)·10⁻³·g·L."""
        return self.mass_g(reading, direction) * self._torque_per_g()

    def torque_std(self, reading, direction=None, include_noise: bool = True) -> np.ndarray:
        """Standard uncertainty (N·m) of :meth:`torque` for one reading."""
        return self.mass_std_g(reading, direction, include_noise) * self._torque_per_g()

    def sample_coefficients(self, n: int, rng: np.random.Generator) -> np.ndarray:
        """``n`` posterior draws of the coefficients, shape (n, p), columns ``coef_names``
        (resampled from the stored thinned chain)."""
        idx = rng.integers(0, self.samples.shape[0], int(n))
        return self.samples[idx]

    def torque_draws(self, reading, n: int, rng: np.random.Generator, direction=None,
                     include_noise: bool = False) -> np.ndarray:
        """Torque of ``reading`` under ``n`` posterior draws, shape (n, *reading.shape)."""
        r = np.asarray(reading, float)
        idx = rng.integers(0, self.samples.shape[0], int(n))
        coefs = self.samples[idx]
        a, b, c, h = (v.reshape((-1,) + (1,) * r.ndim) for v in self._split(coefs))
        rr = r[None]
        if include_noise:
            s = self.sigma_samples[idx].reshape((-1,) + (1,) * r.ndim)
            rr = rr + s * rng.standard_normal((int(n),) + r.shape)
        return self._invert(rr, a, b + h * self._weight(direction), c) * self._torque_per_g()
