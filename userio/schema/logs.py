"""A log's side files: ``LOG.timing.toml`` (how each force channel was sampled) and
``LOG.noise.toml`` (its sensor noise, 1σ per sample). Which channels a file may name depends on
the log's robot: the readers pass them as the validation context (``channels``,
``torque_sizes``, ``ft_sizes``)."""

from __future__ import annotations

from typing import Annotated

from pydantic import AfterValidator, ValidationInfo, field_validator, model_validator

from estimator.noise import (ENCODER_COUNTS_RANGE, FT_SIGMA_RANGE, TORQUE_SIGMA_RANGE,
                             VELOCITY_SIGMA_RANGE)
from userio.errors import nearest
from userio.ranges import Range
from userio.schema.base import Field, Model, fail, integer, num, vector


def _timing(text):
    """'instant' | 'mean' | 'delay:SECONDS' → (kind, delay_s) (estimator.timing.spec)."""
    from estimator.timing import spec

    return spec(text)


Timing = Annotated[str, AfterValidator(_timing)]


class TimingFile(Model):
    """``LOG.timing.toml`` beside ``LOG.csv``: one ``[timing]`` table; a column wins over its group,
    a group over ``default``."""

    timing: dict[str, Timing] = Field(
        description="keys default, wrench (the FT channels), tau (the joint torques) or a channel "
                    "name; values 'instant' (the value at t_k), 'mean' (the mean over the interval "
                    "ending at t_k) or 'delay:SECONDS' (a filter's group delay, ≤ 1 s)")

    @field_validator("timing")
    @classmethod
    def _channels(cls, table, info: ValidationInfo):
        names = (info.context or {}).get("channels")
        if names is not None:
            allowed = ["default", "wrench", "tau", *names]
            for key in table:
                if key not in allowed:
                    raise fail(key, f"unknown channel{nearest(key, allowed)}; use one of "
                               f"{', '.join(allowed)}")
        return table


BASE_ANGLE_SIGMA_RANGE = Range(0.0, 0.5, "rad", high="degrees typed as radians?")
BASE_SPEED_SIGMA_RANGE = Range(0.0, 10.0, "m/s", high="mm/s typed as m/s?")


class NoiseTable(Model):
    """``[noise]``: white sensor noise, 1σ per sample."""

    torque_sigma_Nm: vector(None, TORQUE_SIGMA_RANGE, gt=0) = Field(
        description="joint torque σ: one value, or one per (sensed) joint")
    ft_sigma: vector(None, FT_SIGMA_RANGE, gt=0) = Field(
        description="FT σ: planar [Fx N, Fz N, My N·m]; 3-D [Fx, Fy, Fz N, Mx, My, Mz N·m] or "
                    "[force, moment]")
    velocity_sigma_rad_per_s: num(VELOCITY_SIGMA_RANGE, ge=0) = Field(
        0.0, description="joint-rate noise")
    encoder_counts: integer(ENCODER_COUNTS_RANGE, ge=0) = Field(
        0, description="encoder counts per revolution (0: no quantization)")
    base_orientation_sigma_rad: vector(None, BASE_ANGLE_SIGMA_RANGE, ge=0) = Field(
        [0.0], description="3-D floating base: orientation noise, a rotation vector in the base "
                           "frame (one value or three)")
    base_velocity_sigma_m_per_s: vector(None, BASE_SPEED_SIGMA_RANGE, ge=0) = Field(
        [0.0], description="3-D floating base: noise of ṗ (world; one value or three)")
    base_rate_sigma_rad_per_s: vector(None, VELOCITY_SIGMA_RANGE, ge=0) = Field(
        [0.0], description="3-D floating base: noise of ω (base frame; one value or three)")

    @model_validator(mode="after")
    def _sizes(self, info: ValidationInfo):
        ctx = info.context or {}
        for key, sizes in (("torque_sigma_Nm", ctx.get("torque_sizes")),
                           ("ft_sigma", ctx.get("ft_sizes"))):
            n = len(getattr(self, key))
            if sizes is not None and n not in sizes:
                want = " or ".join(str(s) for s in sorted(set(sizes)))
                raise fail(key, f"expected {want} values, got {n}")
        if ctx.get("planar"):
            for key in ("base_orientation_sigma_rad", "base_velocity_sigma_m_per_s",
                        "base_rate_sigma_rad_per_s"):
                if key in self.model_fields_set:
                    raise fail(key, "a 3-D floating base's noise: a planar log's base state is "
                                    "not estimated from it (remove the key)")
        return self


class NoiseFile(Model):
    """``LOG.noise.toml`` beside ``LOG.csv`` (written by ``simulate``): the sensor noise
    ``estimate`` whitens the residual with."""

    noise: NoiseTable = Field(description="the noise")

