"""A 3-D scene (``simulate`` on a URDF robot): the robot, its controller, pokes on link surfaces,
the sensors. How many joints the vectors need comes from the robot, checked by the reader
(estimator.spatial.scene)."""

from __future__ import annotations

from typing import Literal, Optional, Union

from pydantic import model_validator

from userio.schema.base import Field, Model, fail, integer, num, vector


class UrdfRef(Model):
    """``[robot]``: a bare URDF with the default declaration."""

    urdf: str = Field(description="the URDF, relative to the scene")


class Controller(Model):
    """``[controller]``: joint PD servo to q0 plus a sine of ``amplitude_rad`` at ``frequency_Hz``."""

    q0_rad: Optional[vector()] = Field(None, description="set point, one per joint (default 0)")
    kp: num(ge=0) = Field(60.0, description="stiffness, N·m/rad")
    kd: num(ge=0) = Field(1.5, description="damping, N·m·s/rad")
    amplitude_rad: Optional[vector()] = Field(None, description="sine amplitude per joint (default 0)")
    frequency_Hz: num(ge=0) = Field(1.0, description="sine frequency")


class Poke(Model):
    """``[[poke]]``: a force on a link surface (``along``/``around_rad``) or at ``point_m``."""

    link: str = Field(description="URDF link (or one of its solids)")
    point_m: Optional[vector(3)] = Field(None, description="application point in the link frame")
    along: num(ge=0, le=1) = Field(0.5, description="position along the link's solid, 0..1")
    around_rad: num() = Field(0.0, description="angle around the solid's axis")
    force_N: Optional[vector(3)] = Field(None, description="force in the world frame")
    magnitude_N: Optional[num(gt=0)] = Field(None, description="force into the surface at q0")
    t_on_s: num(ge=0) = Field(description="start")
    t_off_s: num(gt=0) = Field(description="end (after t_on_s)")
    ramp_s: num(ge=0) = Field(0.0, description="linear ramp at each end")

    @model_validator(mode="after")
    def _consistent(self):
        if self.t_off_s <= self.t_on_s:
            raise fail("t_off_s", f"must be after t_on_s = {self.t_on_s:g} s")
        if self.force_N is None and self.point_m is not None:
            raise fail("magnitude_N", "with point_m give force_N (world), or use along/around_rad")
        if self.force_N is None and self.magnitude_N is None:
            raise fail("magnitude_N", "missing field (or give force_N)")
        return self


class Sensors(Model):
    """``[sensors]``: sampling and white noise (none unless a σ is given)."""

    sample_rate_Hz: num(gt=0, le=1e5) = Field(1000.0, description="log sample rate")
    torque_noise_Nm: Optional[num(gt=0)] = Field(None, description="joint torque σ (default 0.005 "
                                                 "when ft_noise is given)")
    ft_noise: Optional[vector(gt=0)] = Field(None, description="FT σ: [force N, moment N·m] or six "
                                             "values (default [0.1, 0.01] when torque_noise_Nm is given)")
    seed: integer(ge=0) = Field(0, description="noise seed")


class Integrator(Model):
    """``[integrator]``."""

    substeps: integer(ge=1, le=1000) = Field(10, description="integration steps per sample")


class SpatialSceneFile(Model):
    """A simulation of a URDF robot (``simulate SCENE.toml`` whose robot is a URDF)."""

    name: Optional[str] = Field(None, description="label (default: the file's stem)")
    description: Optional[str] = Field(None, description="free text")
    robot: Union[str, UrdfRef] = Field(description="a robot declaration or URDF (beside the scene, "
                                       "in a robots/ folder above it, or the repository's robots/), "
                                       "or a table {urdf = FILE}")
    base: Optional[Literal["floating", "fixed"]] = Field(None, description="overrides the declaration")
    duration_s: num(gt=0, le=3600.0) = Field(1.0, description="simulated time")
    controller: Controller = Field(Controller(), description="the joint servo")
    poke: list[Poke] = Field([], description="external forces")
    sensors: Sensors = Field(Sensors(), description="sampling and noise")
    integrator: Integrator = Field(Integrator(), description="the integrator")
