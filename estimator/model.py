"""One interface for a robot's rigid-body model: what the observer, the detector, the localizer and
the identification need from a robot, whatever describes it.

Two implementations: the planar chain of a robot TOML (``estimator.robot.Robot``, the fast special
case with its compiled kernels) and a URDF robot (spatial, pinocchio). Code that needs a robot
takes a ``RobotModel`` and uses only what is declared here; a new kind of robot is a new class
that implements it, never a branch in the code that uses it.

Coordinates are the observer's (docs/conventions.md): the base rows first (``n_base`` = 3 planar
[x, z, θ]; 6 spatial), then one row per joint in ``joint_names`` order. A fixed base is the
floating one held still: its rows carry the base force-torque sensor's wrench, so
τ_meas = [wrench ON the base, joint torques] in every case. Every array function is vectorized
over a leading sample axis T.

Inertial parameters θ (``parameter_names``) enter the dynamics linearly (the rigid-body dynamics
are linear in mass, first moment and inertia of each body), which the identification and the
model-uncertainty terms use:

    P(q, v)       = M(q) v              = Y_P(q, v) θ
    u(q, v) − τ   = Cᵀ(q, v) v − G(q)   = Y_u(q, v) θ        (Ṗ = u + τ_ext, the observer's law)

so the residual's drive under no contact, d = ΔP/Δt − ū, is linear in θ as well, and a parameter
error δθ shows up in the residual as the filtered regressor times δθ.

How far the real robot may be from its file is a covariance Σ_θ of θ (``model_covariance``): the
posterior of an identification (``torquebench identify``), or a declared physical uncertainty
(``ModelUncertainty``: relative masses and inertias, centres of mass in metres) mapped to θ by
``parameter_covariance``. Identification keeps θ physically consistent through
``consistency_margins`` (every entry ≥ 0 exactly when θ is consistent).

Optional, used when a model has them: ``consistency_margin_names`` (what each margin bounds, for
messages), ``n_q`` (columns of q when they are not ``n_v``: a URDF robot's quaternion) and
``fused_model_chi2`` (the model-error statistic with the model's own compiled
regressor inside the loop; estimator.model_error falls back to ``momentum_regressor``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np


@dataclass(frozen=True)
class ModelUncertainty:
    """1σ of a robot file's inertial data, independent per body: masses and rotational inertias
    (about the centre of mass) relative, centres of mass in metres along every axis. ``com_m``
    None: ``relative`` × the body's length (a link's ``length_m``)."""

    mass_rel: float
    inertia_rel: float
    com_m: float | None = None
    relative: float | None = None          # what a single number declared (for messages)

    @classmethod
    def uniform(cls, relative: float) -> "ModelUncertainty":
        """One relative figure for everything: masses, inertias, and COM as a fraction of length."""
        return cls(mass_rel=relative, inertia_rel=relative, com_m=None, relative=relative)

    def describe(self) -> str:
        com = f"{self.com_m * 1e3:g} mm" if self.com_m is not None else \
            f"{self.relative or 0:g} × link length"
        return (f"masses ±{self.mass_rel * 100:g} %, inertias ±{self.inertia_rel * 100:g} %, "
                f"centres of mass ±{com} (1σ)")


@runtime_checkable
class RobotModel(Protocol):
    """What every robot model provides (arrays shaped (T, …); q (T, n_q), v (T, n_v))."""

    name: str
    floating: bool                 # base free in the world, or held (its rows carry the FT wrench)
    n_base: int                    # base rows of v: 3 planar, 6 spatial
    n_v: int                       # n_base + joints
    joint_names: tuple[str, ...]   # joint rows of v, in order
    sensed_joints: tuple[bool, ...]  # which joints carry a torque sensor (unsensed: no equation)

    def momentum_terms(self, q: np.ndarray, v: np.ndarray, tau_meas: np.ndarray):
        """(P, u), each (T, n_v): P = M v, u = τ_meas + Cᵀ v − G."""

    def mass_matrix(self, q: np.ndarray) -> np.ndarray:
        """M(q), (T, n_v, n_v)."""

    # ---- inertial parameters (identification, model uncertainty)
    parameter_names: tuple[str, ...]

    def parameters(self) -> np.ndarray:
        """θ of this model, (n_θ,), in ``parameter_names`` order."""

    def with_parameters(self, theta: np.ndarray) -> "RobotModel":
        """The same robot with inertial parameters θ (geometry, joints and sensors unchanged)."""

    def momentum_regressor(self, q: np.ndarray, v: np.ndarray):
        """(Y_P, Y_u), each (T, n_v, n_θ): P = Y_P θ and Cᵀv − G = Y_u θ (module doc)."""

    def consistency_problems(self, theta: np.ndarray) -> list[str]:
        """Physical consistency of θ (positive masses, centre of mass on the body, positive
        definite inertia satisfying the triangle inequalities); [] when consistent."""

    def consistency_margins(self, theta: np.ndarray) -> np.ndarray:
        """Smooth constraint values of θ, every one ≥ 0 exactly when θ is consistent (what a
        constrained fit keeps ≥ 0)."""

    def consistency_lmis(self, theta: np.ndarray) -> list[np.ndarray]:
        """The consistency conditions as linear matrix inequalities: stacks (B, k, k) of symmetric
        matrices affine in θ, all ⪰ 0 exactly when θ is consistent (≻ 0: strictly); what the
        constrained fit's semidefinite program keeps ⪰ 0."""

    def parameter_covariance(self, uncertainty: ModelUncertainty) -> np.ndarray:
        """Σ_θ (n_θ, n_θ) of a declared physical uncertainty, linearized at this model's θ."""

    def model_covariance(self) -> tuple[np.ndarray | None, str]:
        """(Σ_θ, source) the robot file states: an identification's posterior covariance, else its
        declared model uncertainty; (None, why) when it states neither."""
