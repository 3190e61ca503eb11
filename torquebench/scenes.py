"""Scene files (TOML) → simulation configurations, validated field by field.

Three kinds of scene:

- ``kind = "dynamic"`` (default): one time simulation (estimator.sim.SimConfig): base, controller,
  pokes, optional ground, sensors, integrator.
- ``kind = "static_loading"``: masses hung on the links of a held leg (Table IV); each load is held
  for ``hold_s`` and the static equilibrium readings (estimator.sim.static_readings) are sampled.
- ``kind = "posture_sweep"``: a grid of postures × contact points × one force, same static model.

Every error is a torquebench.errors.InputError naming the file and the field.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from estimator.robot import Robot, load_robot
from estimator.sim.config import (INTEGRATORS, Controller, Ground, Poke, Sensors, SimConfig)
from torquebench.errors import InputError
from torquebench.io import REPO_ROOT
from userio.fields import Fields as _Fields
from userio.files import read_toml

G_M_PER_S2 = 9.81
KINDS = ("dynamic", "static_loading", "posture_sweep")


@dataclass(frozen=True)
class EstimatorSettings:
    method: str = "dynamic"
    gain_per_s: float = 100.0
    threshold: float = 0.06


@dataclass(frozen=True)
class StaticPoint:
    q_rad: np.ndarray
    link: int
    alpha: float
    force_N: np.ndarray
    label: str = ""


@dataclass(frozen=True)
class StaticScene:
    """Static holds: every point is held for ``hold_s``; the estimate is read over the last
    ``window_s`` of each hold (the observer has settled: window starts ≥ 5/K after the change)."""

    name: str
    kind: str
    robot: Robot
    points: tuple[StaticPoint, ...]
    sensors: Sensors
    hold_s: float = 0.15
    window_s: float = 0.08
    grid_shape: tuple = ()


@dataclass(frozen=True)
class Scene:
    name: str
    kind: str
    path: Path
    description: str
    sim: SimConfig | None
    static: StaticScene | None
    estimator: EstimatorSettings = field(default_factory=EstimatorSettings)


def _resolve_robot(f: _Fields, data: dict) -> Robot:
    name = data.get("robot", "paper_leg.toml")
    if not isinstance(name, str):
        raise f.err("robot", f"expected a file name, got {name!r}")
    for cand in (f.path.parent / name, REPO_ROOT / "robots" / name, Path(name)):
        if cand.is_file():
            try:
                return load_robot(cand)
            except InputError as exc:
                raise InputError(f"{f.path}: robot: {exc}") from None
    raise f.err("robot", f"file {name!r} not found beside the scene or in robots/")


def _sensors(f: _Fields, data: dict) -> Sensors:
    t = f.table(data, "sensors")
    f.known(t, {"sample_rate_Hz", "torque_model", "torque_noise_Nm", "ft_noise", "encoder_counts",
                "velocity_noise_rad_per_s", "seed"}, "sensors")
    counts = t.get("encoder_counts", 0)
    if isinstance(counts, bool) or not isinstance(counts, int) or counts < 0:
        raise f.err("sensors.encoder_counts", f"expected an integer ≥ 0, got {counts!r}")
    if t.get("torque_model") == "bridge" and "torque_noise_Nm" in t:   # issue 16: never ignore
        raise f.err("sensors.torque_noise_Nm", "is ignored with torque_model = \"bridge\" (the "
                    "bridge chain sets the noise); remove it or use torque_model = \"gaussian\"")
    seed = t.get("seed", 0)
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise f.err("sensors.seed", f"expected an integer ≥ 0, got {seed!r}")
    return Sensors(
        sample_rate_Hz=f.number(t, "sample_rate_Hz", "sensors", 1000.0, positive=True),
        torque_model=f.choice(t, "torque_model", "sensors", ("gaussian", "bridge"), "gaussian"),
        torque_noise_Nm=f.number(t, "torque_noise_Nm", "sensors", 0.01, nonneg=True),
        ft_noise=f.vector(t, "ft_noise", "sensors", 3, [0.1, 0.1, 0.01], nonneg=True),
        encoder_counts=counts,
        velocity_noise_rad_per_s=f.number(t, "velocity_noise_rad_per_s", "sensors", 0.0, nonneg=True),
        seed=seed)


def _estimator(f: _Fields, data: dict) -> EstimatorSettings:
    t = f.table(data, "estimator")
    f.known(t, {"method", "gain_per_s", "threshold"}, "estimator")
    return EstimatorSettings(
        method=f.choice(t, "method", "estimator", ("dynamic", "paper"), "dynamic"),
        gain_per_s=f.number(t, "gain_per_s", "estimator", 100.0, positive=True),
        threshold=f.number(t, "threshold", "estimator", 0.06, positive=True))


def _poke(f: _Fields, p: dict, where: str, n_links: int, duration: float) -> Poke:
    if not isinstance(p, dict):
        raise f.err(where, "expected a table")
    f.known(p, {"link", "alpha", "magnitude_N", "direction_rad", "mass_kg", "t_on_s", "t_off_s",
                "ramp_s"}, where)
    link = p.get("link")
    if isinstance(link, bool) or not isinstance(link, int) or not 1 <= link <= n_links:
        raise f.err(f"{where}.link", f"expected an integer in 1..{n_links}, got {link!r}")
    if "mass_kg" in p:
        if "magnitude_N" in p or "direction_rad" in p:
            raise f.err(f"{where}.mass_kg", "give either mass_kg or magnitude_N + direction_rad")
        mag = f.number(p, "mass_kg", where, positive=True) * G_M_PER_S2
        direction = -math.pi / 2
    else:
        mag = f.number(p, "magnitude_N", where, nonneg=True)
        direction = f.number(p, "direction_rad", where)
    t_on = f.number(p, "t_on_s", where, 0.0, nonneg=True)
    t_off = f.number(p, "t_off_s", where, duration, nonneg=True)
    if t_off < t_on:
        raise f.err(f"{where}.t_off_s", f"must be ≥ t_on_s = {t_on}, got {t_off}")
    return Poke(link=link, alpha=f.number(p, "alpha", where, lo=0.0, hi=1.0), magnitude_N=mag,
                direction_rad=direction, t_on_s=t_on, t_off_s=t_off,
                ramp_s=f.number(p, "ramp_s", where, 0.0, nonneg=True))


def _dynamic(f: _Fields, data: dict, robot: Robot, name: str) -> SimConfig:
    base = f.choice(data, "base", "", ("floating", "fixed", "rigid"), "floating")
    duration = f.number(data, "duration_s", "", 1.5, positive=True)
    n = robot.n_links
    c = f.table(data, "controller", required=True)
    f.known(c, {"q0_rad", "kp", "kd", "mode", "rate_Hz", "amplitude_rad", "frequency_Hz",
                "phase_rad", "gravity_compensation"}, "controller")
    traj = {}
    if any(k in c for k in ("amplitude_rad", "frequency_Hz", "phase_rad")):
        traj = dict(amplitude_rad=f.vector(c, "amplitude_rad", "controller", n),
                    frequency_Hz=f.vector(c, "frequency_Hz", "controller", n, nonneg=True),
                    phase_rad=f.vector(c, "phase_rad", "controller", n, np.zeros(n)))
    gc = c.get("gravity_compensation", False)
    if not isinstance(gc, bool):
        raise f.err("controller.gravity_compensation", f"expected true or false, got {gc!r}")
    controller = Controller(
        q0_rad=f.vector(c, "q0_rad", "controller", n),
        kp=f.number(c, "kp", "controller", 500.0, nonneg=True),
        kd=f.number(c, "kd", "controller", 10.0, nonneg=True),
        mode=f.choice(c, "mode", "controller", ("continuous", "zoh"), "continuous"),
        rate_Hz=f.number(c, "rate_Hz", "controller", 1000.0, positive=True),
        gravity_compensation=gc, **traj)
    pokes_raw = data.get("poke", [])
    if not isinstance(pokes_raw, list):
        raise f.err("poke", "expected [[poke]] tables")
    pokes = tuple(_poke(f, p, f"poke[{i}]", n, duration) for i, p in enumerate(pokes_raw, 1))
    spans = sorted((p.t_on_s, p.t_off_s + p.ramp_s, i) for i, p in enumerate(pokes, 1)
                   if p.t_off_s > p.t_on_s)
    for (a0, a1, i), (b0, b1, j) in zip(spans, spans[1:]):
        if b0 < a1:
            raise f.err(f"poke[{j}].t_on_s", f"overlaps poke[{i}] (one contact at a time: the "
                        "truth file holds one)")
    g = data.get("ground")
    ground = None
    if g is not None:
        if not isinstance(g, dict):
            raise f.err("ground", "expected a table")
        f.known(g, {"height_m", "stiffness_N_per_m", "damping_Ns_per_m",
                    "tangential_stiffness_N_per_m", "friction_coefficient"}, "ground")
        ground = Ground(
            height_m=f.number(g, "height_m", "ground", 0.0),
            stiffness_N_per_m=f.number(g, "stiffness_N_per_m", "ground", 2e4, positive=True),
            damping_Ns_per_m=f.number(g, "damping_Ns_per_m", "ground", 200.0, nonneg=True),
            tangential_stiffness_N_per_m=f.number(g, "tangential_stiffness_N_per_m", "ground",
                                                  2e4, positive=True),
            friction_coefficient=f.number(g, "friction_coefficient", "ground",
                                          robot.friction_coefficient, nonneg=True))
        if base == "rigid":
            raise f.err("ground", "a ground contact needs base = \"floating\" or \"fixed\"")
    it = f.table(data, "integrator")
    f.known(it, {"method", "rtol", "atol", "fixed_step_s"}, "integrator")
    m = f.table(data, "mount")
    f.known(m, {"stiffness", "damping"}, "mount")
    if m and base == "rigid":
        raise f.err("mount", "a rigid base has no mount springs")
    return SimConfig(
        robot=robot, controller=controller, base=base, duration_s=duration, pokes=pokes,
        ground=ground, sensors=_sensors(f, data),
        integrator=f.choice(it, "method", "integrator", INTEGRATORS, "BDF"),
        rtol=f.number(it, "rtol", "integrator", 1e-6, lo=1e-13, hi=1e-2),   # issue 16: a 1 %
        atol=f.number(it, "atol", "integrator", 1e-8, positive=True, hi=1e-2),  # cap, ≥ 100 eps
        fixed_step_s=f.number(it, "fixed_step_s", "integrator", 5e-5, positive=True),
        mount_stiffness=f.vector(m, "stiffness", "mount", 3, nonneg=True) if m else None,
        mount_damping=f.vector(m, "damping", "mount", 3, nonneg=True) if m else None,
        name=name)


def _static(f: _Fields, data: dict, robot: Robot, name: str, kind: str) -> StaticScene:
    n = robot.n_links
    hold = f.table(data, "hold")
    f.known(hold, {"hold_s", "window_s"}, "hold")
    hold_s = f.number(hold, "hold_s", "hold", 0.15, positive=True)
    window_s = f.number(hold, "window_s", "hold", 0.08, positive=True)
    if window_s > hold_s:
        raise f.err("hold.window_s", f"must be ≤ hold_s = {hold_s}, got {window_s}")
    points, shape = [], ()
    if kind == "static_loading":
        q = f.vector(data, "q_rad", "", n)
        loads = data.get("load")
        if not isinstance(loads, list) or not loads:
            raise f.err("load", "expected at least one [[load]] table")
        for i, ld in enumerate(loads, 1):
            where = f"load[{i}]"
            if not isinstance(ld, dict):
                raise f.err(where, "expected a table")
            f.known(ld, {"link", "mass_kg", "alpha"}, where)
            link = ld.get("link")
            if isinstance(link, bool) or not isinstance(link, int) or not 1 <= link <= n:
                raise f.err(f"{where}.link", f"expected an integer in 1..{n}, got {link!r}")
            masses = f.vector(ld, "mass_kg", where, nonneg=True)
            alphas = f.vector(ld, "alpha", where)
            if np.any((alphas < 0) | (alphas > 1)):
                raise f.err(f"{where}.alpha", f"values must lie in [0, 1], got {alphas.tolist()}")
            for mass in masses:
                for a in alphas:
                    points.append(StaticPoint(q, link, float(a),
                                              np.array([0.0, -mass * G_M_PER_S2]),
                                              f"link {link}, {mass * 1000:g} g"))
    else:
        grid = f.table(data, "grid", required=True)
        f.known(grid, {"q1_rad", "q2_rad", "count"}, "grid")
        if n != 2:
            raise f.err("grid", f"the posture sweep is defined for 2 links, robot has {n}")
        count = grid.get("count", 10)
        if isinstance(count, bool) or not isinstance(count, int) or count < 1:
            raise f.err("grid.count", f"expected an integer ≥ 1, got {count!r}")
        r1 = f.vector(grid, "q1_rad", "grid", 2)
        r2 = f.vector(grid, "q2_rad", "grid", 2)
        c = f.table(data, "contact", required=True)
        f.known(c, {"links", "alpha", "magnitude_N", "direction_rad"}, "contact")
        links = f.vector(c, "links", "contact")
        if np.any((links < 1) | (links > n) | (links != np.round(links))):
            raise f.err("contact.links", f"expected link numbers in 1..{n}, got {links.tolist()}")
        alphas = f.vector(c, "alpha", "contact")
        if np.any((alphas < 0) | (alphas > 1)):
            raise f.err("contact.alpha", f"values must lie in [0, 1], got {alphas.tolist()}")
        mag = f.number(c, "magnitude_N", "contact", positive=True)
        beta = f.number(c, "direction_rad", "contact")
        F = mag * np.array([math.cos(beta), math.sin(beta)])
        q1s, q2s = np.linspace(*r1, count), np.linspace(*r2, count)
        shape = (count, count, len(links), len(alphas))
        for q1 in q1s:
            for q2 in q2s:
                for link in links:
                    for a in alphas:
                        points.append(StaticPoint(np.array([q1, q2]), int(link), float(a), F))
    return StaticScene(name=name, kind=kind, robot=robot.with_base(False), points=tuple(points),
                       sensors=_sensors(f, data), hold_s=hold_s, window_s=window_s,
                       grid_shape=shape)


def load_scene(path: str | Path) -> Scene:
    """Read and validate a scene file."""
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: scene file not found")
    data = read_toml(path)
    f = _Fields(path)
    f.known(data, {"name", "description", "kind", "robot", "base", "duration_s", "controller",
                   "poke", "ground", "sensors", "integrator", "mount", "estimator", "hold", "q_rad",
                   "load", "grid", "contact"}, "")
    name = data.get("name", path.stem)
    if not isinstance(name, str):
        raise f.err("name", f"expected a string, got {name!r}")
    kind = f.choice(data, "kind", "", KINDS, "dynamic")
    robot = _resolve_robot(f, data)
    desc = str(data.get("description", ""))
    est = _estimator(f, data)
    if kind == "dynamic":
        return Scene(name, kind, path, desc, _dynamic(f, data, robot, name), None, est)
    return Scene(name, kind, path, desc, None, _static(f, data, robot, name, kind), est)


def scene_path(name: str) -> Path:
    """A shipped scene by name (``paper_floating_link1``) or a path."""
    p = Path(name)
    if p.suffix == ".toml" and p.is_file():
        return p
    cand = REPO_ROOT / "scenes" / (name if name.endswith(".toml") else f"{name}.toml")
    if not cand.is_file():
        raise InputError(f"--scene: no scene {name!r} (looked for {cand})")
    return cand


def with_overrides(scene: Scene, **kw) -> Scene:
    """A copy with SimConfig fields replaced (integrator, duration_s, seed via sensors...)."""
    if scene.sim is None:
        return scene
    return replace(scene, sim=replace(scene.sim, **kw))
