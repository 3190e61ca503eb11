"""A calibration file (JSON written by ``calibrate``, e.g. calibration/data/paper_link1_cal.json).

Its content hash (``content_sha256``) is checked first (calibration.store.read_document); this
schema then refuses a hash-valid document that does not make sense: unknown model, coefficients
missing or not finite, slope 0, lever arm not in (0, 10] m, covariance missing, not square, not
symmetric or not positive semi-definite, posterior draws of the wrong shape.
"""

from __future__ import annotations

from typing import Any, Literal, Optional

import numpy as np
from pydantic import model_validator

from calibration.session import LEVER_ARM_RANGE_M
from userio.schema.base import Field, Model, fail, num, vector

MODEL_COEFS = {"linear": ("slope", "offset"), "quadratic": ("slope", "offset", "quad"),
               "hysteresis": ("slope", "offset", "hysteresis")}


class Stats(Model):
    """Posterior summary of one quantity."""

    mean: num() = Field(description="posterior mean")
    std: num(ge=0) = Field(description="posterior standard deviation")
    p16: num() = Field(description="16th percentile")
    p50: num() = Field(description="median")
    p84: num() = Field(description="84th percentile")


class Covariance(Model):
    """``covariance``: of the coefficients (the torque's uncertainty needs it)."""

    names: list[str] = Field(description="the coefficients, in the model's order")
    matrix: list[vector()] = Field(description="symmetric positive semi-definite, p × p")


class Samples(Model):
    """``samples``: posterior draws."""

    names: list[str] = Field(description="the coefficients, then log_sigma")
    values: list[vector()] = Field(min_length=1, description="draws, one row each (S × (p + 1))")


class CalibrationFile(Model):
    """A fitted sensor model ``reading = slope·mass_g + offset (+ quad·mass_g² | + hysteresis·[unloading])``."""

    schema_id: Literal["torquebench.calibration"] = Field(alias="schema", description="file format")
    schema_version: Literal[1] = Field(description="file format version")
    sensor_id: str = Field("", description="the sensor calibrated")
    model: Literal[tuple(MODEL_COEFS)] = Field(description="linear, quadratic or hysteresis")
    reading_unit: str = Field("", description="unit of the readings (mV, counts, …)")
    mass_unit: Literal["g"] = Field("g", description="unit of the applied masses")
    lever_arm_m: Optional[num(LEVER_ARM_RANGE_M, gt=0)] = Field(
        None, description="calibration lever: torque = mass·g·lever_arm_m (none: mass only)")
    equation: str = Field("", description="the model, in words")
    coefficients: dict[str, num()] = Field(description="posterior means of the model's coefficients")
    posterior: dict[str, Stats] = Field(description="posterior summary per coefficient and sigma")
    covariance: Covariance = Field(description="coefficient covariance")
    samples: Samples = Field(description="posterior draws")
    diagnostics: Optional[dict[str, Any]] = Field(None, description="MCMC diagnostics")
    ols: Optional[dict[str, Any]] = Field(None, description="least-squares fit")
    exact: Optional[dict[str, Any]] = Field(None, description="exact (Student-t) marginals")
    characterization: Optional[dict[str, Any]] = Field(
        None, description="nonlinearity, hysteresis, repeatability (calibration.characterize)")
    calibrated_range: Optional[dict[str, Any]] = Field(None, description="masses and readings seen")
    data: Optional[dict[str, Any]] = Field(None, description="the session: path, sha256, readings")
    provenance: Optional[dict[str, Any]] = Field(None, description="when and with what")
    content_sha256: Optional[str] = Field(None, description="SHA-256 of the canonical JSON without it")

    @model_validator(mode="after")
    def _meaning(self):
        names = MODEL_COEFS[self.model]
        if set(self.coefficients) != set(names):
            raise fail("coefficients", f"model {self.model!r} needs exactly {', '.join(names)}")
        if self.coefficients["slope"] == 0:
            raise fail("coefficients.slope", "slope is 0; readings carry no load information")
        if "sigma" not in self.posterior:
            raise fail("posterior.sigma", "missing field")
        if self.posterior["sigma"].mean < 0:
            raise fail("posterior.sigma.mean", "must be ≥ 0")
        cov = self.covariance
        if list(cov.names) != list(names):
            raise fail("covariance.names", f"expected {list(names)}, got {cov.names!r}")
        p = len(names)
        if len(cov.matrix) != p or any(len(r) != p for r in cov.matrix):
            raise fail("covariance.matrix", f"expected a finite {p}×{p} matrix")
        mat = np.asarray(cov.matrix, float)
        if not np.allclose(mat, mat.T, rtol=1e-9, atol=0):
            raise fail("covariance.matrix", "not symmetric")
        lam = np.linalg.eigvalsh(mat)
        if lam.min() < -1e-9 * max(abs(lam).max(), 1e-300):
            raise fail("covariance.matrix", f"not positive semi-definite (eigenvalue {lam.min():.3g})")
        if any(len(r) != p + 1 for r in self.samples.values):
            raise fail("samples.values", f"expected finite draws of shape (S, {p + 1})")
        return self
