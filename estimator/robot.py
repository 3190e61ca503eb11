"""Robot descriptions: a planar serial chain on a floating or fixed base, read from TOML.

Conventions (docs/conventions.md): link i runs from p_i to p_{i+1} = p_i + l_i e_i with
e_i = (sin φ_i, −cos φ_i), φ_i = θ + q_1 + … + q_i; its centre of mass is
c_i = p_i + r_i e_i + s_i n_i, n_i = (cos φ_i, sin φ_i) = e_i rotated +90° (r_i = ``com_m``
along the axis, s_i = ``com_perp_m`` across it, positive on the +x side of a link hanging
straight down); I_i is about that centre of mass. The base's centre of mass is the base origin
p_1 (the hip).

``Robot`` implements ``estimator.model.RobotModel`` (inertial parameters, regressor,
consistency: estimator.inertial); an identified file carries its ``[identification]`` table and a
file may declare ``[model_uncertainty]`` (how far the real robot may be from it).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from userio.files import read_toml


@dataclass(frozen=True)
class Robot:
    """A planar serial chain. Arrays have one entry per link (N = ``n_links``)."""

    lengths_m: np.ndarray
    com_m: np.ndarray
    masses_kg: np.ndarray
    inertias_kgm2: np.ndarray
    base_mass_kg: float
    base_inertia_kgm2: float
    floating: bool = True
    gravity_m_per_s2: float = 9.81
    base_stiffness: np.ndarray = field(default_factory=lambda: np.zeros(3))
    base_damping: np.ndarray = field(default_factory=lambda: np.zeros(3))
    friction_coefficient: float = 0.3
    name: str = "robot"
    com_perp_m: np.ndarray | None = None       # centre of mass across the link axis (None: 0)
    model_uncertainty: object | None = None    # declared ModelUncertainty (estimator.model)
    identification: dict | None = None         # the [identification] table of an identified file

    def __post_init__(self):
        if self.com_perp_m is None:
            object.__setattr__(self, "com_perp_m", np.zeros(len(self.lengths_m)))

    @property
    def n_links(self) -> int:
        return len(self.lengths_m)

    # ---------------------------------------------------------------- estimator.model.RobotModel
    n_base = 3

    @property
    def n_v(self) -> int:
        """Observer rows [x, z, θ, q_1…q_N], floating or fixed (a fixed base's rows carry the FT)."""
        return self.n_links + 3

    @property
    def joint_names(self) -> tuple[str, ...]:
        return tuple(f"q{i}" for i in range(1, self.n_links + 1))

    @property
    def sensed_joints(self) -> tuple[bool, ...]:
        return (True,) * self.n_links

    @property
    def parameter_names(self) -> tuple[str, ...]:
        from estimator import inertial

        return inertial.parameter_names(self.n_links)

    def parameters(self) -> np.ndarray:
        from estimator import inertial

        return inertial.parameters(self)

    def with_parameters(self, theta) -> "Robot":
        from estimator import inertial

        return inertial.with_parameters(self, theta)

    def momentum_terms(self, q, v, tau_meas):
        from estimator.observer import momentum_terms

        return momentum_terms(self, q, v, tau_meas)

    def mass_matrix(self, q) -> np.ndarray:
        from estimator.dynamics import mass_matrix

        return mass_matrix(self.with_base(True), q)

    def momentum_regressor(self, q, v):
        from estimator import inertial

        return inertial.momentum_regressor(self, q, v)

    def fused_model_chi2(self, q, dq, bufs, *args) -> bool:
        """The model-error statistic with this chain's compiled regressor fused into its loop
        (estimator.model_error.ModelTerm; model_kernels.planar_model_chi2); False without numba."""
        from estimator import model_kernels

        return model_kernels.planar_model_chi2(self, q, dq, bufs, *args)

    def consistency_problems(self, theta) -> list[str]:
        from estimator import inertial

        return inertial.consistency_problems(self, theta)

    def consistency_margins(self, theta) -> np.ndarray:
        from estimator import inertial

        return inertial.consistency_margins(self, theta)

    def consistency_lmis(self, theta) -> list[np.ndarray]:
        from estimator import inertial

        return inertial.consistency_lmis(self, theta)

    @property
    def consistency_margin_names(self) -> list[str]:
        from estimator import inertial

        return inertial.margin_names(self.n_links)

    def parameter_covariance(self, uncertainty) -> np.ndarray:
        from estimator import inertial

        return inertial.parameter_covariance(self, uncertainty)

    def model_covariance(self):
        """(Σ_θ, source) this file states: its identification's covariance, else its declared
        [model_uncertainty], else (None, why)."""
        from estimator import inertial

        return inertial.model_covariance(self)

    @property
    def n_coords(self) -> int:
        """Generalized coordinates: [x, z, θ, q_1…q_N] floating, [q_1…q_N] fixed."""
        return self.n_links + (3 if self.floating else 0)

    def with_base(self, floating: bool) -> "Robot":
        """The same chain on the other kind of base."""
        from dataclasses import replace

        return replace(self, floating=floating)


def robot_from_dict(data: dict, source: str = "robot") -> Robot:
    """A robot description (``robots/paper_leg.toml``) validated by its schema
    (userio.schema.robot.RobotFile: known keys, finite numbers in their physical ranges, each
    centre of mass on its link) → Robot; InputError naming the file and field."""
    from estimator import inertial
    from userio.schema import parse
    from userio.schema.robot import RobotFile

    file = parse(RobotFile, data, source)
    col = lambda key: np.array([getattr(link, key) for link in file.link], float)   # noqa: E731
    robot = Robot(
        lengths_m=col("length_m"), com_m=col("com_m"), masses_kg=col("mass_kg"),
        inertias_kgm2=col("inertia_kgm2"), com_perp_m=col("com_perp_m"),
        base_mass_kg=file.base_body.mass_kg, base_inertia_kgm2=file.base_body.inertia_kgm2,
        floating=(file.base == "floating"), gravity_m_per_s2=file.gravity_m_per_s2,
        base_stiffness=np.array(file.base_mount.stiffness, float),
        base_damping=np.array(file.base_mount.damping, float),
        friction_coefficient=file.friction_coefficient,
        name=Path(source).stem if file.name is None else file.name)
    _warn_mass_units(robot.masses_kg, source)
    return inertial.read_tables(robot, file, source)


#: links of one chain whose masses differ by this factor or more: one of them in another unit
MASS_RATIO_UNITS = 1000.0


def _warn_mass_units(masses_kg, source: str) -> None:
    """Warn (estimator.plausibility.PlausibilityWarning) when the heaviest link weighs ≥ 1000×
    the lightest: the factor of a mass typed in g among masses in kg (each value alone lies in
    its range, so the schema cannot see it)."""
    m = np.asarray(masses_kg, float)
    if len(m) < 2 or not np.all(m > 0) or m.max() < MASS_RATIO_UNITS * m.min():
        return
    import warnings

    from estimator.plausibility import PlausibilityWarning

    hi, lo = int(np.argmax(m)), int(np.argmin(m))
    warnings.warn(f"{source}: link[{hi + 1}].mass_kg = {m[hi]:g} is {m[hi] / m[lo]:.0f}× link[{lo + 1}]'s "
                  f"({m[lo]:g} kg): one of them in g?", PlausibilityWarning, stacklevel=3)


def load_robot(path: str | Path) -> Robot:
    """Read and validate a robot TOML file; errors name the file and field."""
    path = Path(path)
    return robot_from_dict(read_toml(path), source=str(path))


PAPER_LEG_TOML = Path(__file__).resolve().parents[1] / "robots" / "paper_leg.toml"


def paper_leg(floating: bool = True) -> Robot:
    """The paper's leg (Table I, I_base = 0.002 kg·m², Table II base mount)."""
    return load_robot(PAPER_LEG_TOML).with_base(floating)
