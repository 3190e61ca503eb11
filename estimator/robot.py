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

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from estimator.errors import InputError
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


def _physical_ranges():
    """The physical range of each Robot field, with its unit (userio.fields.Range), keyed by the
    field and naming the TOML key: checked once a description is read (``check_physical``)."""
    from userio.fields import Range

    return {
        "lengths_m": ("link[{i}].length_m", Range(1e-3, 10.0, "m", low="µm? a link is longer than 1 mm",
                                                  high="mm typed as m?")),
        "masses_kg": ("link[{i}].mass_kg", Range(1e-4, 1e3, "kg", low="below 0.1 g", high="g typed as kg?")),
        "inertias_kgm2": ("link[{i}].inertia_kgm2", Range(1e-10, 1e3, "kg·m²", high="g·mm² or kg·cm² mix-up?")),
        "base_mass_kg": ("base_body.mass_kg", Range(1e-4, 1e4, "kg", high="g typed as kg?")),
        "base_inertia_kgm2": ("base_body.inertia_kgm2", Range(1e-10, 1e4, "kg·m²")),
        "gravity_m_per_s2": ("gravity_m_per_s2", Range(1.0, 30.0, "m/s²", low="with g ≈ 0 nothing "
                                                       "weighs on the sensors the estimator reads "
                                                       "(the Moon's is 1.6)", high="mm/s² typed as m/s²?")),
        "base_stiffness": ("base_mount.stiffness", Range(0.0, 1e12, "N/m or N·m/rad")),
        "base_damping": ("base_mount.damping", Range(0.0, 1e9, "N·s/m or N·m·s/rad")),
    }


def check_physical(robot: Robot, source: str = "robot") -> Robot:
    """Every field of ``robot`` inside its physical range (InputError naming file and key)."""
    for name, (key, rng) in _physical_ranges().items():
        values = np.atleast_1d(np.asarray(getattr(robot, name), float))
        for i, v in enumerate(values, start=1):
            why = rng.problem(float(v))
            if why:
                raise InputError(f"{source}: {key.format(i=i)}: {why}")
    return robot


def _number(table: dict, key: str, where: str, *, positive=False, nonneg=False) -> float:
    if key not in table:
        raise InputError(f"{where}: missing field '{key}'")
    value = table[key]
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise InputError(f"{where}.{key}: expected a finite number, got {value!r}")
    if positive and value <= 0:
        raise InputError(f"{where}.{key}: must be > 0, got {value}")
    if nonneg and value < 0:
        raise InputError(f"{where}.{key}: must be ≥ 0, got {value}")
    return float(value)


def _triple(table: dict, key: str, where: str) -> np.ndarray:
    value = table.get(key, [0.0, 0.0, 0.0])
    if (not isinstance(value, list) or len(value) != 3
            or not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in value)):
        raise InputError(f"{where}.{key}: expected three numbers [x, z, θ], got {value!r}")
    arr = np.asarray(value, dtype=float)
    if not np.all(np.isfinite(arr)) or np.any(arr < 0):
        raise InputError(f"{where}.{key}: values must be finite and ≥ 0, got {value}")
    return arr


MAX_LINKS = 64                       # links of one planar chain (a leg has 2–4)
TOP_KEYS = {"name", "base", "gravity_m_per_s2", "friction_coefficient", "link", "base_body",
            "base_mount", "model_uncertainty", "identification"}
LINK_KEYS = {"length_m", "com_m", "com_perp_m", "mass_kg", "inertia_kgm2"}
BODY_KEYS = {"mass_kg", "inertia_kgm2"}
MOUNT_KEYS = {"stiffness", "damping"}


def _known(table: dict, allowed: set, where: str) -> None:
    """Unknown key → InputError naming it, with the nearest valid key (userio.fields)."""
    from userio.fields import nearest

    extra = sorted(set(table) - allowed)
    if extra:
        raise InputError(f"{where}.{extra[0]}: unknown field{nearest(extra[0], allowed)} "
                         f"(allowed: {', '.join(sorted(allowed))})")


def _table(value, where: str) -> dict:
    if not isinstance(value, dict):
        raise InputError(f"{where}: expected a table, got {type(value).__name__}")
    return value


def robot_from_dict(data: dict, source: str = "robot") -> Robot:
    """Validate a robot description (the TOML schema of ``robots/paper_leg.toml``): known keys
    only, finite numbers, positive lengths/masses/inertias, COM on its link 0 ≤ r_i ≤ l_i,
    gravity in [0, 100] m/s², friction coefficient in [0, 10]."""
    _known(_table(data, source), TOP_KEYS, source)
    base = data.get("base", "floating")
    if base not in ("floating", "fixed"):
        raise InputError(f"{source}: field 'base' must be \"floating\" or \"fixed\", got {base!r}")
    links = data.get("link")
    if not isinstance(links, list) or not links:
        raise InputError(f"{source}: missing [[link]] tables (at least one link is needed)")
    if len(links) > MAX_LINKS:
        raise InputError(f"{source}: {len(links)} [[link]] tables, above the {MAX_LINKS} links of a "
                         "planar chain this estimator handles")
    rows = []
    for i, link in enumerate(links, start=1):
        where = f"{source}: link[{i}]"
        _known(_table(link, where), LINK_KEYS, where)
        length = _number(link, "length_m", where, positive=True)
        com = _number(link, "com_m", where, nonneg=True)
        if com > length:
            raise InputError(f"{where}.com_m: centre of mass {com:g} m lies beyond the link's end "
                             f"(length_m = {length:g}); need 0 ≤ com_m ≤ length_m")
        perp = _number(link, "com_perp_m", where) if "com_perp_m" in link else 0.0
        if abs(perp) > length:
            raise InputError(f"{where}.com_perp_m: centre of mass {perp:g} m off the link axis, more "
                             f"than the link's length ({length:g} m); need |com_perp_m| ≤ length_m")
        rows.append((length, com, _number(link, "mass_kg", where, positive=True),
                     _number(link, "inertia_kgm2", where, positive=True), perp))
    lengths, coms, masses, inertias, perps = (np.array(c) for c in zip(*rows))
    body = data.get("base_body")
    if not isinstance(body, dict):
        raise InputError(f"{source}: missing [base_body] table (mass_kg, inertia_kgm2)")
    _known(body, BODY_KEYS, f"{source}: base_body")
    mount = _table(data.get("base_mount", {}), f"{source}: base_mount")
    _known(mount, MOUNT_KEYS, f"{source}: base_mount")
    if "gravity_m_per_s2" in data and not 0 <= _number(data, "gravity_m_per_s2", source) <= 100:
        raise InputError(f"{source}.gravity_m_per_s2: must lie in [0, 100] m/s², "
                         f"got {data['gravity_m_per_s2']}")
    if "friction_coefficient" in data and _number(data, "friction_coefficient", source) > 10:
        raise InputError(f"{source}.friction_coefficient: must lie in [0, 10], "
                         f"got {data['friction_coefficient']}")
    robot = Robot(
        lengths_m=lengths, com_m=coms, masses_kg=masses, inertias_kgm2=inertias, com_perp_m=perps,
        base_mass_kg=_number(body, "mass_kg", f"{source}: base_body", positive=True),
        base_inertia_kgm2=_number(body, "inertia_kgm2", f"{source}: base_body", positive=True),
        floating=(base == "floating"),
        gravity_m_per_s2=_number(data, "gravity_m_per_s2", source, nonneg=True)
        if "gravity_m_per_s2" in data else 9.81,
        base_stiffness=_triple(mount, "stiffness", f"{source}: base_mount"),
        base_damping=_triple(mount, "damping", f"{source}: base_mount"),
        friction_coefficient=_number(data, "friction_coefficient", source, nonneg=True)
        if "friction_coefficient" in data else 0.3,
        name=_name(data, source),
    )
    if "model_uncertainty" in data or "identification" in data:
        from estimator import inertial

        robot = inertial.read_tables(robot, data, source)
    return check_physical(robot, source)


def _name(data: dict, source: str) -> str:
    name = data.get("name", Path(source).stem)
    if not isinstance(name, str):
        raise InputError(f"{source}.name: expected a string, got {name!r}")
    return name


def load_robot(path: str | Path) -> Robot:
    """Read and validate a robot TOML file; errors name the file and field."""
    path = Path(path)
    return robot_from_dict(read_toml(path), source=str(path))


PAPER_LEG_TOML = Path(__file__).resolve().parents[1] / "robots" / "paper_leg.toml"


def paper_leg(floating: bool = True) -> Robot:
    """The paper's leg (Table I, I_base = 0.002 kg·m², Table II base mount)."""
    return load_robot(PAPER_LEG_TOML).with_base(floating)
