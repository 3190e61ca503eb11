"""A planar robot description (``robots/paper_leg.toml``): links, base body, base mount.

Conventions (docs/conventions.md): link i runs from joint i along its axis; ``com_m`` along that
axis from the proximal joint, ``com_perp_m`` across it; inertias about each centre of mass.
"""

from __future__ import annotations

from typing import Any, Literal, Optional

from pydantic import model_validator

from userio.schema.base import Field, Model, Range, fail, num, vector

MAX_LINKS = 64                       # links of one planar chain (a leg has 2–4)

LENGTH = Range(1e-3, 10.0, "m", low="µm? a link is longer than 1 mm", high="mm typed as m?")
MASS = Range(1e-4, 1e3, "kg", low="below 0.1 g", high="g typed as kg?")
INERTIA = Range(1e-10, 1e3, "kg·m²", high="g·mm² or kg·cm² mix-up?")
BASE_MASS = Range(1e-4, 1e4, "kg", high="g typed as kg?")
BASE_INERTIA = Range(1e-10, 1e4, "kg·m²")
GRAVITY = Range(1.0, 30.0, "m/s²", low="with g ≈ 0 nothing weighs on the sensors the estimator "
                "reads (the Moon's is 1.6)", high="mm/s² typed as m/s²?")
STIFFNESS = Range(0.0, 1e12, "N/m or N·m/rad")
DAMPING = Range(0.0, 1e9, "N·s/m or N·m·s/rad")


class Link(Model):
    """One ``[[link]]`` table, from the base outwards."""

    length_m: num(LENGTH, gt=0) = Field(description="joint-to-joint length")
    com_m: num(ge=0) = Field(description="centre of mass along the link axis from the proximal "
                             "joint, 0 ≤ com_m ≤ length_m")
    com_perp_m: num() = Field(0.0, description="centre of mass across the axis (+x side of a link "
                              "hanging down), |com_perp_m| ≤ length_m")
    mass_kg: num(MASS, gt=0) = Field(description="link mass")
    inertia_kgm2: num(INERTIA, gt=0) = Field(description="rotational inertia about the link's "
                                             "centre of mass")

    @model_validator(mode="after")
    def _com_on_link(self):
        if self.com_m > self.length_m:
            raise fail("com_m", f"centre of mass {self.com_m:g} m lies beyond the link's end "
                       f"(length_m = {self.length_m:g}); need 0 ≤ com_m ≤ length_m")
        if abs(self.com_perp_m) > self.length_m:
            raise fail("com_perp_m", f"centre of mass {self.com_perp_m:g} m off the link axis, more "
                       f"than the link's length ({self.length_m:g} m); need |com_perp_m| ≤ length_m")
        return self


class BaseBody(Model):
    """``[base_body]``: the body the first joint is mounted on (its centre of mass is the hip)."""

    mass_kg: num(BASE_MASS, gt=0) = Field(description="base mass")
    inertia_kgm2: num(BASE_INERTIA, gt=0) = Field(description="inertia about the base origin")


class BaseMount(Model):
    """``[base_mount]``: spring-dampers holding the base; the FT sensor reads their wrench."""

    stiffness: vector(3, STIFFNESS, ge=0) = Field(
        (0.0, 0.0, 0.0), description="[x N/m, z N/m, θ N·m/rad]")
    damping: vector(3, DAMPING, ge=0) = Field(
        (0.0, 0.0, 0.0), description="[x N·s/m, z N·s/m, θ N·m·s/rad]")


REL = Range(0.0, 1.0, "")


class ModelUncertaintyTable(Model):
    """``[model_uncertainty]``: how far the real robot may be from the file, each 1σ; ``relative``
    for everything, or ``mass_rel``, ``inertia_rel`` and ``com_m``."""

    relative: Optional[num(REL)] = Field(None, description="relative 1σ of every mass and inertia, "
                                         "COM as a fraction of the link length")
    mass_rel: Optional[num(REL)] = Field(None, description="relative 1σ of the masses")
    inertia_rel: Optional[num(REL)] = Field(None, description="relative 1σ of the inertias")
    com_m: Optional[num(Range(0.0, 1.0, "m"))] = Field(None, description="1σ of the centres of mass")

    @model_validator(mode="after")
    def _complete(self):
        if self.relative is None:
            for k in ("mass_rel", "inertia_rel", "com_m"):
                if getattr(self, k) is None:
                    raise fail(k, "missing field (or give relative for all)")
        return self


class IdentificationTable(Model):
    """``[identification]``, written by ``identify``: checked against the file's own inertial data."""

    parameter_names: list[str] = Field(description="the robot's inertial parameters, in order")
    parameters: vector() = Field(description="their identified values (equal to the file's data)")
    covariance: list[vector()] = Field(description="their covariance, symmetric positive "
                                       "semi-definite")
    nominal_parameters: Any = Field(None, description="the parameters before identification")
    source_robot: Any = Field(None, description="the robot file identified")
    source_robot_sha256: Any = Field(None, description="its SHA-256")
    logs: Any = Field(None, description="the logs used")
    statistics: Any = Field(None, description="fit statistics")
    unexcited: Any = Field(None, description="parameters the logs did not excite")
    created_utc: Any = Field(None, description="when")
    command: Any = Field(None, description="the command line")
    method: Any = Field(None, description="the estimator used")
    notes: Any = Field(None, description="free text")


class RobotFile(Model):
    """A planar serial chain on a floating or fixed base (``--robot FILE.toml``)."""

    name: Optional[str] = Field(None, description="label (default: the file's stem)")
    base: Literal["floating", "fixed"] = Field(
        "floating", description="floating: x, z, θ free on the mount; fixed: welded to the world")
    gravity_m_per_s2: num(GRAVITY) = Field(9.81, description="g; gravity is (0, −g) in the x–z plane")
    friction_coefficient: num(ge=0, le=10) = Field(0.3, description="μ, foot–ground Coulomb friction")
    link: list[Link] = Field(min_length=1, max_length=MAX_LINKS,
                             description="the links, base outwards (at least one)")
    base_body: BaseBody = Field(description="the base's mass and inertia")
    base_mount: BaseMount = Field(BaseMount(), description="the base's spring-dampers")
    model_uncertainty: Optional[ModelUncertaintyTable] = Field(
        None, description="how far the real robot may be from this file")
    identification: Optional[IdentificationTable] = Field(
        None, description="written by `identify`: the identified parameters and their covariance")


# --------------------------------------------------------------------------- a URDF robot
COLLISION_SIZES = {"box": 3, "cylinder": 2, "capsule": 2, "sphere": 1, "mesh": 3}


class Collision(Model):
    """``[[collision]]``: replaces the URDF's solids of one link (kind "none": no geometry, the
    link is then located on its segment)."""

    link: str = Field(description="the URDF link")
    kind: Literal["box", "cylinder", "capsule", "sphere", "mesh", "none"] = Field(
        description="solid kind")
    size: Optional[vector(gt=0)] = Field(None, description="box [x, y, z]; cylinder, capsule "
                                         "[radius, length]; sphere [radius]; mesh scale [x, y, z] "
                                         "(default 1); metres")
    xyz: vector(3) = Field((0.0, 0.0, 0.0), description="origin in the link frame, m")
    rpy: vector(3) = Field((0.0, 0.0, 0.0), description="roll, pitch, yaw in the link frame, rad")
    mesh: Optional[str] = Field(None, description="mesh file (kind = \"mesh\"), relative to this file")

    @model_validator(mode="after")
    def _sized(self):
        if self.kind == "none":
            return self
        n = COLLISION_SIZES[self.kind]
        if self.size is None and self.kind != "mesh":
            raise fail("size", "missing field")
        if self.size is not None and len(self.size) != n:
            raise fail("size", f"expected {n} numbers, got {len(self.size)}")
        if self.kind == "mesh" and self.mesh is None:
            raise fail("mesh", "missing field")
        return self


class Mount(Model):
    """``[mount]``: the rig's spring-dampers between the world and the FT sensor frame."""

    pose_xyz: vector(3) = Field((0.0, 0.0, 0.0), description="base position at rest (world), m")
    pose_rpy: vector(3) = Field((0.0, 0.0, 0.0), description="base roll, pitch, yaw at rest, rad")
    stiffness: vector(6, STIFFNESS, ge=0) = Field(
        (2e4, 2e4, 2e4, 800.0, 800.0, 800.0), description="x, y, z [N/m]; rx, ry, rz [N·m/rad]")
    damping: vector(6, DAMPING, ge=0) = Field(
        (150.0, 150.0, 150.0, 4.0, 4.0, 4.0), description="[N·s/m] ×3, [N·m·s/rad] ×3")


class SpatialRobotFile(Model):
    """A URDF robot's declaration (``robots/quadruped_leg.toml``)."""

    name: Optional[str] = Field(None, description="label (default: the file's stem)")
    urdf: str = Field(description="the URDF file, relative to this file")
    base: Literal["floating", "fixed"] = Field(
        "floating", description="floating: on the mount springs; fixed: welded at the mount pose")
    torque_sensed: Optional[list[str]] = Field(
        None, description="joints with a torque sensor (default: every joint)")
    ft_frame: Optional[str] = Field(None, description="URDF link/frame of the FT sensor, fixed to "
                                    "the base (default: the root link)")
    gravity_m_per_s2: num(GRAVITY) = Field(9.81, description="g; gravity is (0, 0, −g) in the world")
    mount: Mount = Field(Mount(), description="the rig's spring-dampers")
    collision: list[Collision] = Field([], description="solids replacing the URDF's, per link")
    model_uncertainty: Optional[ModelUncertaintyTable] = Field(
        None, description="how far the real robot may be from this file")
    identification: Optional[IdentificationTable] = Field(
        None, description="written by `identify`: the identified parameters and their covariance")
