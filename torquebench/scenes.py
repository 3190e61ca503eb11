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
import os
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from estimator.robot import Robot, load_robot
from estimator.sim.config import (INTEGRATORS, Controller, Ground, Poke, Sensors, SimConfig)
from estimator.limits import ALPHA_RANGE, FORCE_RANGE, GAIN_RANGE, SAMPLE_RATE_RANGE, THRESHOLD_RANGE
from estimator.noise import FT_SIGMA_RANGE, TORQUE_SIGMA_RANGE
from torquebench.errors import InputError
from torquebench.io import REPO_ROOT
from userio.fields import Fields as _Fields
from userio.fields import Range, ranged
from userio.files import read_toml

G_M_PER_S2 = 9.81
KINDS = ("dynamic", "static_loading", "posture_sweep")


@dataclass(frozen=True)
class EstimatorSettings:
    """[estimator]: threshold None → ``dynamic`` detects with the chi-square test at
    ``false_alarm_rate`` (value, unit 'sample' | 's' | 'h') on the residual whitened by the scene's
    sensor noise (pipeline.scene_noise_model); ``paper`` keeps ε = 0.06. A threshold given → the
    paper's rule ‖r‖ > threshold for both methods. ``quiet_window_s`` (t0, t1): the residual's
    covariance is estimated robustly from that contact-free stretch of the log instead (the way to
    state the noise of a recorded log, whose sensors the scene does not describe)."""

    method: str = "dynamic"
    gain_per_s: float = ranged(100.0, GAIN_RANGE)
    threshold: float | None = ranged(None, THRESHOLD_RANGE)
    false_alarm_rate: tuple = (1.0, "h")
    quiet_window_s: tuple | None = None


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
class ChainSpec:
    """What the scene gives for the sensor chain (torquebench.pipeline reads it).

    ``[flexure]``: ``design`` (a flexure TOML, run through the FEM) or ``strain_per_Nm``;
    ``[sensor]``: ``file`` (bridge/amplifier/ADC TOML) and ``true_gain_factor`` (the real sensor's
    gain over its model: 1.05 = 5 % more sensitive than calibrated, for validation);
    ``[calibration]``: ``file`` (a stored calibration JSON) or a simulated loading session
    (``masses_g``, ``lever_arm_m``, ``repeats``, ``n_avg``, ``seed``) fitted with emcee;
    ``[source]``: ``log`` (a recorded CSV, optionally with raw sensor ``counts_columns`` holding
    ``reading_unit`` "counts" (ADC codes, the default) or "mV", which a stored calibration must
    read) or, when absent, the simulation of the scene's top-level keys; ``[outputs] want = [...]``.
    """

    flexure_design: Path | None = None
    strain_per_Nm: float | None = None
    sensor_file: Path | None = None
    true_gain_factor: float = 1.0
    calibration_file: Path | None = None
    session: dict | None = None              # masses_g, lever_arm_m, repeats, n_avg, seed
    log_file: Path | None = None
    counts_columns: tuple = ()
    outputs: tuple = ()
    reading_unit: str = "counts"             # what counts_columns hold: raw ADC "counts" or "mV"
    report_areas: tuple | None = None        # [outputs] reports (None: every area the scene feeds)
    report_dir: Path | None = None           # [outputs] dir (None: ./out/<scene name>)
    regenerate_shipped: bool = False         # [outputs] regenerate_shipped: may write reports/


@dataclass(frozen=True)
class PredictionSpec:
    """A posture-grid localization-error prediction (what `propagate` asks): contact (link, α),
    force (magnitude, direction from +x), ``grid`` postures per joint over [0, π], Monte Carlo
    ``draws`` and ``seed``, sample rate, observer gain, FT noise σ (Fx, Fz, My); an optional
    given joint-torque σ (else the sensor chain's) and gain error (else the calibration's), the
    robot's model uncertainty; the bound maps' hold time and number of force directions."""

    link: int
    alpha: float = ranged(0.8, ALPHA_RANGE)
    magnitude_N: float = ranged(7.0, FORCE_RANGE)
    direction_rad: float = 0.0
    grid: int = ranged(10, Range(1, 1000, "postures per joint"))
    draws: int = ranged(500, Range(2, 1e7, "draws per posture"))
    seed: int = 0
    sample_rate_Hz: float = ranged(1000.0, SAMPLE_RATE_RANGE)
    gain_per_s: float = ranged(100.0, GAIN_RANGE)
    ft_noise: tuple = ranged((0.1, 0.1, 0.01), FT_SIGMA_RANGE)
    torque_noise_Nm: float | None = ranged(None, TORQUE_SIGMA_RANGE)
    gain_error: float | None = ranged(None, Range(0.0, 1.0, "(relative)"))
    model_uncertainty: float | None = ranged(None, Range(0.0, 1.0, "(relative)"))   # 1σ of the
    # inertial data (0: none; None: the robot file's identification or [model_uncertainty])
    hold_s: float = 0.5                  # the episode bound's hold time (estimator.bound_maps)
    directions: int = 24                 # force directions of the bound maps


@dataclass(frozen=True)
class Scene:
    name: str
    kind: str
    path: Path
    description: str
    sim: SimConfig | None
    static: StaticScene | None
    estimator: EstimatorSettings = field(default_factory=EstimatorSettings)
    chain: ChainSpec = field(default_factory=ChainSpec)
    robot: Robot | None = None
    prediction: PredictionSpec | None = None
    max_run_time_s: float = 600.0          # a run limit, not an input: not part of any cache key
    robot_file: Path | None = None         # the robot TOML the scene named (an input of the run)


def scene_inputs(scene: Scene) -> list[tuple[str, Path]]:
    """Every file a run of ``scene`` reads, labelled by its field (for the output policy,
    userio.outputs: none of them may be written): the scene, its robot, flexure design, sensor and
    calibration files, and a recorded log with its side files (LOG.timing.toml, LOG.noise.toml)."""
    from userio.outputs import log_side_files

    ch = scene.chain
    items = [("scene", scene.path), ("robot", scene.robot_file), ("flexure.design", ch.flexure_design),
             ("sensor.file", ch.sensor_file), ("calibration.file", ch.calibration_file),
             ("source.log", ch.log_file)]
    if ch.log_file is not None:
        items += [("source.log's side file", p) for p in log_side_files(ch.log_file)]
    return [(label, Path(p)) for label, p in items if p is not None and not str(p).startswith("<")]


def _robot_path(f: _Fields, data: dict) -> Path | None:
    """The robot file a scene names, resolved as ``_resolve_robot`` resolves it (None: not found)."""
    name = data.get("robot", "paper_leg.toml")
    if isinstance(name, dict):
        name = name.get("file", "paper_leg.toml")
    if not isinstance(name, str):
        return None
    for cand in (f.path.parent / name, REPO_ROOT / "robots" / name, Path(name)):
        if cand.is_file():
            return cand
    return None


ROBOT_KEYS = {"file", "true_parameters", "perturbation", "perturbation_seed"}


def _robot_file(f: _Fields, name, where: str) -> Robot:
    if not isinstance(name, str):
        raise f.err(where, f"expected a file name, got {name!r}")
    for cand in (f.path.parent / name, REPO_ROOT / "robots" / name, Path(name)):
        if cand.is_file():
            try:
                return load_robot(cand)
            except InputError as exc:
                raise InputError(f"{f.path}: {where}: {exc}") from None
    raise f.err(where, f"file {name!r} not found beside the scene or in robots/")


def _resolve_robot(f: _Fields, data: dict) -> Robot:
    """The robot file the estimator reads: ``robot = "x.toml"`` or ``[robot] file = "x.toml"``."""
    name = data.get("robot", "paper_leg.toml")
    if isinstance(name, dict):                       # [robot] file = "..."
        f.known(name, ROBOT_KEYS, "robot")
        name = f.string(name, "file", "robot", "paper_leg.toml")
    return _robot_file(f, name, "robot")


def _true_robot(f: _Fields, data: dict, robot: Robot, kind: str) -> Robot:
    """The robot the simulator simulates: the file's, or (a dynamic scene's [robot] table)
    ``true_parameters = "other.toml"`` (same links, other inertial data) or a ``perturbation``
    (relative 1σ of masses, inertias and, × link length, centres of mass; drawn with
    ``perturbation_seed``, estimator.inertial.perturbed)."""
    from estimator.inertial import perturbed
    from estimator.model import ModelUncertainty

    t = data.get("robot")
    if not isinstance(t, dict) or not (set(t) & {"true_parameters", "perturbation"}):
        if isinstance(t, dict) and "perturbation_seed" in t:
            raise f.err("robot.perturbation_seed", "is the seed of a perturbation; set robot.perturbation")
        return robot
    if kind != "dynamic":
        raise f.err("robot", "true_parameters / perturbation: only a dynamic scene simulates a "
                    "robot other than its file")
    if "true_parameters" in t and "perturbation" in t:
        raise f.err("robot.perturbation", "give either true_parameters or a perturbation, not both")
    if "true_parameters" in t:
        true = _robot_file(f, t["true_parameters"], "robot.true_parameters")
        if true.n_links != robot.n_links or not np.allclose(true.lengths_m, robot.lengths_m):
            raise f.err("robot.true_parameters", f"{true.name} has links {true.lengths_m.tolist()} m, "
                        f"the file {robot.name} {robot.lengths_m.tolist()} m: only inertial data "
                        "may differ")
        from dataclasses import replace

        return replace(true, floating=robot.floating)
    rel = f.number(t, "perturbation", "robot", lo=0.0, hi=0.5)
    seed = f.integer(t, "perturbation_seed", "robot", 0, lo=0)
    return perturbed(robot, ModelUncertainty.uniform(rel), seed) if rel > 0 else robot


def _sensors(f: _Fields, data: dict) -> Sensors:
    t = f.table(data, "sensors")
    f.known(t, {"sample_rate_Hz", "torque_model", "torque_noise_Nm", "ft_noise", "encoder_counts",
                "velocity_noise_rad_per_s", "seed"}, "sensors")
    counts = t.get("encoder_counts", 0)
    if isinstance(counts, bool) or not isinstance(counts, int) or counts < 0:
        raise f.err("sensors.encoder_counts", f"expected an integer ≥ 0, got {counts!r}")
    if t.get("torque_model") == "bridge" and "torque_noise_Nm" in t:   # never ignore
        raise f.err("sensors.torque_noise_Nm", "is ignored with torque_model = \"bridge\" (the "
                    "bridge chain sets the noise); remove it or use torque_model = \"gaussian\"")
    seed = t.get("seed", 0)
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise f.err("sensors.seed", f"expected an integer ≥ 0, got {seed!r}")
    return f.ranges(Sensors(
        sample_rate_Hz=f.number(t, "sample_rate_Hz", "sensors", 1000.0, positive=True),
        torque_model=f.choice(t, "torque_model", "sensors", ("gaussian", "bridge"), "gaussian"),
        torque_noise_Nm=f.number(t, "torque_noise_Nm", "sensors", 0.01, nonneg=True),
        ft_noise=f.vector(t, "ft_noise", "sensors", 3, [0.1, 0.1, 0.01], nonneg=True),
        encoder_counts=counts,
        velocity_noise_rad_per_s=f.number(t, "velocity_noise_rad_per_s", "sensors", 0.0, nonneg=True),
        seed=seed), "sensors")


def _estimator(f: _Fields, data: dict) -> EstimatorSettings:
    from estimator.noise import parse_rate, per_sample_rate

    t = f.table(data, "estimator")
    f.known(t, {"method", "gain_per_s", "threshold", "false_alarm_rate", "quiet_window_s"},
            "estimator")
    where = f"{f.path}: estimator.false_alarm_rate"
    raw = t.get("false_alarm_rate", "1/h")
    if isinstance(raw, bool) or not isinstance(raw, (str, int, float)):
        raise f.err("estimator.false_alarm_rate", f"expected a rate like \"1/h\", got {raw!r}")
    rate = parse_rate(str(raw), where)
    rate_Hz = f.number(data.get("sensors", {}) if isinstance(data.get("sensors"), dict) else {},
                       "sample_rate_Hz", "sensors", 1000.0, positive=True)
    per_sample_rate(*rate, 1.0 / rate_Hz, where)           # (0, 1) per sample, or one line
    return f.ranges(EstimatorSettings(
        method=f.choice(t, "method", "estimator", ("dynamic", "paper"), "dynamic"),
        gain_per_s=f.number(t, "gain_per_s", "estimator", 100.0, positive=True),
        threshold=f.number(t, "threshold", "estimator", None, positive=True) if "threshold" in t
        else None,
        false_alarm_rate=rate, quiet_window_s=_quiet_window(f, t)), "estimator")


def _quiet_window(f: _Fields, t: dict) -> tuple | None:
    """[estimator] quiet_window_s = [t0, t1] (s, t0 < t1), or None."""
    if "quiet_window_s" not in t:
        return None
    t0, t1 = f.vector(t, "quiet_window_s", "estimator", length=2, nonneg=True)
    if not t1 > t0:
        raise f.err("estimator.quiet_window_s", f"expected [t0, t1] with t0 < t1, got {[t0, t1]}")
    return (float(t0), float(t1))


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
    if t_on >= duration:
        raise f.err(f"{where}.t_on_s", f"{t_on:g} s starts at or after the end of the simulation "
                    f"(duration_s = {duration:g} s): the poke would never act; start it earlier or "
                    "lengthen duration_s")
    return f.ranges(Poke(link=link, alpha=f.number(p, "alpha", where, lo=0.0, hi=1.0), magnitude_N=mag,
                         direction_rad=direction, t_on_s=t_on, t_off_s=t_off,
                         ramp_s=f.number(p, "ramp_s", where, 0.0, nonneg=True)), where,
                    {"magnitude_N": "mass_kg × g" if "mass_kg" in p else "magnitude_N"})


def _harmonics(f: _Fields, c: dict, key: str, n: int, H=None, default=None, nonneg=False):
    """[controller] amplitude_rad / frequency_Hz / phase_rad: one number per joint, or per joint a
    list of H harmonics (a Fourier excitation); a list of lists must match the amplitudes' shape."""
    v = c.get(key)
    if v is None and default is not None:
        return np.asarray(default, float)
    if isinstance(v, list) and v and all(isinstance(row, list) for row in v):
        if len(v) != n:
            raise f.err(f"controller.{key}", f"expected {n} rows (one per joint), got {len(v)}")
        width = H if H else len(v[0])                 # every joint: the same harmonics
        return np.stack([f.vector({key: row}, key, "controller", width, nonneg=nonneg) for row in v])
    if H is not None:
        raise f.err(f"controller.{key}", f"expected {n} lists of {H} harmonics (as amplitude_rad)")
    return f.vector(c, key, "controller", n, default, nonneg=nonneg)


def _dynamic(f: _Fields, data: dict, robot: Robot, name: str) -> SimConfig:
    base = f.choice(data, "base", "", ("floating", "fixed", "rigid"), "floating")
    duration = f.number(data, "duration_s", "", 1.5, positive=True)
    n = robot.n_links
    c = f.table(data, "controller", required=True)
    f.known(c, {"q0_rad", "kp", "kd", "mode", "rate_Hz", "amplitude_rad", "frequency_Hz",
                "phase_rad", "gravity_compensation"}, "controller")
    traj = {}
    if any(k in c for k in ("amplitude_rad", "frequency_Hz", "phase_rad")):
        amp = _harmonics(f, c, "amplitude_rad", n)
        H = amp.shape[1] if amp.ndim == 2 else None
        traj = dict(amplitude_rad=amp,
                    frequency_Hz=_harmonics(f, c, "frequency_Hz", n, H, nonneg=True),
                    phase_rad=_harmonics(f, c, "phase_rad", n, H, np.zeros(amp.shape)))
    gc = c.get("gravity_compensation", False)
    if not isinstance(gc, bool):
        raise f.err("controller.gravity_compensation", f"expected true or false, got {gc!r}")
    controller = f.ranges(Controller(
        q0_rad=f.vector(c, "q0_rad", "controller", n),
        kp=f.number(c, "kp", "controller", 500.0, nonneg=True),
        kd=f.number(c, "kd", "controller", 10.0, nonneg=True),
        mode=f.choice(c, "mode", "controller", ("continuous", "zoh"), "continuous"),
        rate_Hz=f.number(c, "rate_Hz", "controller", 1000.0, positive=True),
        gravity_compensation=gc, **traj), "controller")
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
        ground = f.ranges(Ground(
            height_m=f.number(g, "height_m", "ground", 0.0),
            stiffness_N_per_m=f.number(g, "stiffness_N_per_m", "ground", 2e4, positive=True),
            damping_Ns_per_m=f.number(g, "damping_Ns_per_m", "ground", 200.0, nonneg=True),
            tangential_stiffness_N_per_m=f.number(g, "tangential_stiffness_N_per_m", "ground",
                                                  2e4, positive=True),
            friction_coefficient=f.number(g, "friction_coefficient", "ground",
                                          robot.friction_coefficient, nonneg=True)), "ground")
        if base == "rigid":
            raise f.err("ground", "a ground contact needs base = \"floating\" or \"fixed\"")
    it = f.table(data, "integrator")
    f.known(it, {"method", "rtol", "atol", "fixed_step_s"}, "integrator")
    m = f.table(data, "mount")
    f.known(m, {"stiffness", "damping"}, "mount")
    if m and base == "rigid":
        raise f.err("mount", "a rigid base has no mount springs")
    sensors = _sensors(f, data)
    if controller.frequency_Hz is not None:
        nyq = 0.5 * sensors.sample_rate_Hz
        f_max = float(np.max(controller.frequency_Hz))       # every joint's every harmonic
        if f_max >= nyq:
            raise f.err("controller.frequency_Hz", f"{f_max:g} Hz is at or above the "
                        f"log's Nyquist frequency {nyq:g} Hz (sensors.sample_rate_Hz = "
                        f"{sensors.sample_rate_Hz:g}): the motion could not be sampled")
    return f.ranges(SimConfig(
        robot=robot, controller=controller, base=base, duration_s=duration, pokes=pokes,
        ground=ground, sensors=sensors,
        integrator=f.choice(it, "method", "integrator", INTEGRATORS, "BDF"),
        rtol=f.number(it, "rtol", "integrator", 1e-6, lo=1e-13, hi=1e-2),   # a 1 %
        atol=f.number(it, "atol", "integrator", 1e-8, positive=True, hi=1e-2),  # cap, ≥ 100 eps
        fixed_step_s=f.number(it, "fixed_step_s", "integrator", 5e-5, positive=True),
        mount_stiffness=f.vector(m, "stiffness", "mount", 3, nonneg=True) if m else None,
        mount_damping=f.vector(m, "damping", "mount", 3, nonneg=True) if m else None,
        name=name), "", {"mount_stiffness": "mount.stiffness", "mount_damping": "mount.damping",
                         "fixed_step_s": "integrator.fixed_step_s"})


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


SESSION_KEYS = {"masses_g", "lever_arm_m", "repeats", "n_avg", "seed"}
MAX_SESSION_SAMPLES = 2e7            # ADC codes a simulated calibration session draws (160 MB)


def _file(f: _Fields, table: dict, key: str, where: str, shipped: str) -> Path:
    """A file named in the scene: beside the scene, else in the repository's ``shipped`` folder."""
    name = f.string(table, key, where)
    for cand in (f.path.parent / name, REPO_ROOT / shipped / name, Path(name)):
        if cand.is_file():
            return cand
    raise f.err(f"{where}.{key}", f"file {name!r} not found beside the scene or in {shipped}/")


def _chain_spec(f: _Fields, data: dict, kind: str) -> ChainSpec:
    fx = f.table(data, "flexure")
    f.known(fx, {"design", "strain_per_Nm"}, "flexure")
    if "design" in fx and "strain_per_Nm" in fx:
        raise f.err("flexure.strain_per_Nm", "give either a flexure design or a strain_per_Nm, not both")
    design = _file(f, fx, "design", "flexure", "scenes") if "design" in fx else None
    spn = f.number(fx, "strain_per_Nm", "flexure", positive=True) if "strain_per_Nm" in fx else None
    se = f.table(data, "sensor")
    f.known(se, {"file", "true_gain_factor"}, "sensor")
    sensor_file = _file(f, se, "file", "sensor", "scenes") if "file" in se else None
    gain = f.number(se, "true_gain_factor", "sensor", 1.0, positive=True)
    ca = f.table(data, "calibration")
    f.known(ca, {"file"} | SESSION_KEYS, "calibration")
    cal_file, session = None, None
    if "file" in ca:
        extra = sorted(set(ca) & SESSION_KEYS)
        if extra:
            raise f.err(f"calibration.{extra[0]}", "give either a calibration file or a simulated "
                        "session, not both")
        cal_file = _file(f, ca, "file", "calibration", "calibration/data")
    elif ca:
        masses = f.vector(ca, "masses_g", "calibration", positive=True,
                          default=[10, 20, 50, 100, 200, 300, 500, 700, 850, 1000])
        if masses.size < 3:
            raise f.err("calibration.masses_g", f"need at least 3 load levels, got {masses.size}")
        from calibration.session import LEVER_ARM_RANGE_M, MASS_RANGE_G

        for m_g in masses:
            if MASS_RANGE_G.problem(float(m_g)):
                raise f.err("calibration.masses_g", MASS_RANGE_G.problem(float(m_g)))
        session = {"masses_g": masses.tolist(),
                   "lever_arm_m": f.number(ca, "lever_arm_m", "calibration", 0.205, positive=True),
                   "repeats": f.integer(ca, "repeats", "calibration", 3, lo=1, hi=10_000),
                   "n_avg": f.integer(ca, "n_avg", "calibration", 256, lo=1, hi=10_000_000),
                   "seed": f.integer(ca, "seed", "calibration", 0, lo=0)}
        if LEVER_ARM_RANGE_M.problem(session["lever_arm_m"]):
            raise f.err("calibration.lever_arm_m", LEVER_ARM_RANGE_M.problem(session["lever_arm_m"]))
        n = len(masses) * session["repeats"] * session["n_avg"]
        if n > MAX_SESSION_SAMPLES:          # the simulated session holds every ADC code at once
            raise f.err("calibration.n_avg", f"{len(masses)} masses × {session['repeats']} repeats × "
                        f"n_avg {session['n_avg']} = {n:.3g} ADC samples ({8 * n / 2**30:.3g} GiB) to "
                        f"simulate, above {MAX_SESSION_SAMPLES:.0e}; lower n_avg or repeats")
    so = f.table(data, "source")
    f.known(so, {"log", "counts_columns", "reading_unit"}, "source")
    log_file = _file(f, so, "log", "source", "samples") if "log" in so else None
    cols = so.get("counts_columns", [])
    if not isinstance(cols, list) or not all(isinstance(c, str) for c in cols):
        raise f.err("source.counts_columns", f"expected a list of column names, got {cols!r}")
    if cols and log_file is None:
        raise f.err("source.counts_columns", "counts columns need a recorded log (source.log)")
    if cols and cal_file is None and session is None:
        raise f.err("source.counts_columns", "raw ADC counts need a [calibration] to become torques")
    unit = f.choice(so, "reading_unit", "source", ("counts", "mV"), "counts")
    if "reading_unit" in so and not cols:
        raise f.err("source.reading_unit", "says what source.counts_columns hold; there are none")
    if cols and session is not None and unit != "counts":
        raise f.err("source.reading_unit", f"the simulated calibration session reads ADC counts, "
                    f"but source.counts_columns hold {unit!r}")
    if cols and cal_file is not None:
        from calibration.store import read_document

        cal_unit = read_document(cal_file).get("reading_unit")
        if cal_unit != unit:
            raise f.err("calibration.file", f"{cal_file.name} converts readings in {cal_unit!r}, but "
                        f"source.counts_columns hold {unit!r} (source.reading_unit); give a "
                        f"calibration fitted to {unit!r} readings or set source.reading_unit")
    out = f.table(data, "outputs")
    f.known(out, {"want", "reports", "dir", "regenerate_shipped"}, "outputs")
    want = out.get("want", [])
    if not isinstance(want, list) or not all(isinstance(w, str) for w in want):
        raise f.err("outputs.want", f"expected a list of output names, got {want!r}")
    from torquebench.stages.registry import scene_outputs

    OUTPUTS = scene_outputs()                 # what the stage declarations let a scene ask for
    for w in want:
        if w not in OUTPUTS:
            raise f.err("outputs.want", f"unknown output {w!r}{_nearest(w, OUTPUTS)} "
                        f"(known: {', '.join(OUTPUTS)})")
    areas, report_dir, shipped = _report_fields(f, out, "report" in want)
    return ChainSpec(design, spn, sensor_file, gain, cal_file, session, log_file, tuple(cols),
                     tuple(want), unit, areas, report_dir, shipped)


def report_areas_available() -> list[str]:
    """The report builders: every module torquebench/reports/<area>.py (not imported here)."""
    import pkgutil

    import torquebench.reports

    return sorted(i.name for i in pkgutil.iter_modules(torquebench.reports.__path__)
                  if not i.name.startswith("_"))


def _report_fields(f: _Fields, out: dict, wanted: bool):
    """[outputs] reports / dir / regenerate_shipped: which builders, and where they write."""
    given = sorted(set(out) & {"reports", "dir", "regenerate_shipped"})
    if given and not wanted:
        raise f.err(f"outputs.{given[0]}", "is about reports, but outputs.want has no \"report\"")
    areas = None
    if "reports" in out:
        areas = out["reports"]
        known = report_areas_available()
        if not isinstance(areas, list) or not areas or not all(isinstance(a, str) for a in areas):
            raise f.err("outputs.reports", f"expected a non-empty list of report areas, got {areas!r}")
        for a in areas:
            if a not in known:
                raise f.err("outputs.reports", f"unknown report area {a!r}{_nearest(a, known)} "
                            f"(known: {', '.join(known)})")
        areas = tuple(dict.fromkeys(areas))
    shipped = out.get("regenerate_shipped", False)
    if not isinstance(shipped, bool):
        raise f.err("outputs.regenerate_shipped", f"expected true or false, got {shipped!r}")
    shipped_dir = (REPO_ROOT / "reports").resolve()
    if "dir" in out:
        report_dir = Path(f.string(out, "dir", "outputs"))
        if shipped and report_dir.resolve() != shipped_dir:
            raise f.err("outputs.regenerate_shipped", f"writes the shipped {shipped_dir}; "
                        "drop outputs.dir or this flag")
    else:
        report_dir = shipped_dir if shipped else None
    if report_dir is not None and report_dir.resolve() == shipped_dir and not shipped:
        raise f.err("outputs.dir", f"{report_dir} is the shipped reports directory; set "
                    "outputs.regenerate_shipped = true to replace the shipped reports")
    if report_dir is not None and report_dir.exists() and not report_dir.is_dir():
        raise f.err("outputs.dir", f"{report_dir} exists and is not a directory")
    return areas, report_dir, shipped


def _nearest(key, allowed) -> str:
    from userio.fields import nearest
    return nearest(key, allowed)


def set_key(data: dict, key: str, value, path) -> None:
    """Set a dotted scene key (``calibration.seed``, ``poke.1.alpha``: list items 1-based)."""
    if key == "flexure":          # --vary flexure=a.toml,b.toml (a design) or =5e-5,1e-4 (strain per N·m)
        data["flexure"] = {"design" if isinstance(value, str) else "strain_per_Nm": value}
        return
    parts, node = key.split("."), data
    for i, part in enumerate(parts):
        last = i == len(parts) - 1
        if isinstance(node, list):
            if not part.isdigit() or not 1 <= int(part) <= len(node):
                raise InputError(f"{path}: --vary {key}: {part!r} is not an item 1..{len(node)}")
            if last:
                node[int(part) - 1] = value
            else:
                node = node[int(part) - 1]
        elif last:
            node[part] = value
        else:
            node = node.setdefault(part, {})
            if not isinstance(node, (dict, list)):
                raise InputError(f"{path}: --vary {key}: {part!r} is not a table")


def load_scene(path: str | Path, overrides: dict | None = None) -> Scene:
    """Read and validate a scene file (``overrides``: dotted keys set before validation)."""
    path = Path(path)
    data = read_toml(path)                         # a regular file: not found, a directory or a device say so
    for key, value in (overrides or {}).items():
        set_key(data, key, value, path)
    f = _Fields(path)
    f.known(data, {"name", "description", "kind", "robot", "base", "duration_s", "controller",
                   "poke", "ground", "sensors", "integrator", "mount", "estimator", "hold", "q_rad",
                   "load", "grid", "contact", "flexure", "sensor", "calibration", "source",
                   "outputs"}, "")
    name = data.get("name", path.stem)
    if not isinstance(name, str):
        raise f.err("name", f"expected a string, got {name!r}")
    kind = f.choice(data, "kind", "", KINDS, "dynamic")
    robot = _resolve_robot(f, data)
    true_robot = _true_robot(f, data, robot, kind)
    desc = str(data.get("description", ""))
    est = _estimator(f, data)
    chain = _chain_spec(f, data, kind)
    rfile = _robot_path(f, data)
    if kind == "dynamic" and chain.log_file is not None:
        sim_keys = sorted(set(data) & {"controller", "poke", "ground", "integrator", "mount"})
        if sim_keys:
            raise f.err(sim_keys[0], "a scene with a recorded log (source.log) has no simulation keys")
        return Scene(name, kind, path, desc, None, None, est, chain, robot, robot_file=rfile)
    if kind == "dynamic":
        return Scene(name, kind, path, desc, _dynamic(f, data, true_robot, name), None, est, chain,
                     robot, robot_file=rfile)
    return Scene(name, kind, path, desc, None, _static(f, data, robot, name, kind), est, chain, robot,
                 robot_file=rfile)


def scene_path(name: str) -> Path:
    """A shipped scene by name (``paper_floating_link1``) or a path."""
    from userio.files import check_input

    p = Path(name)
    if os.path.lexists(p) and (p.suffix == ".toml" or os.sep in str(name) or not p.is_file()):
        return check_input(p, what="scene TOML")            # a path the user named: what it is
    if p.is_file():
        return p
    cand = REPO_ROOT / "scenes" / (name if name.endswith(".toml") else f"{name}.toml")
    if not cand.is_file():
        raise InputError(f"--scene: no scene {name!r} (looked for {cand})")
    return cand


def prediction_scene(robot: Robot, chain: ChainSpec, prediction: PredictionSpec,
                     name: str = "propagate") -> Scene:
    """A scene with no simulation that asks for a posture-grid prediction (built by `propagate`
    from its options; every setting inside its physical range, named by its option)."""
    from userio.fields import check_ranges

    check_ranges(prediction, keys={"alpha": "--contact (α)", "magnitude_N": "--force (magnitude)",
                                   "grid": "--grid", "draws": "--draws", "sample_rate_Hz": "--rate",
                                   "gain_per_s": "--gain", "ft_noise": "--ft-noise",
                                   "torque_noise_Nm": "--torque-noise-Nm", "gain_error": "--gain-error"})
    return Scene(name, "prediction", Path(f"<{name} options>"), "", None, None,
                 chain=chain, robot=robot, prediction=prediction)


def with_seed(scene: Scene, seed: int | None) -> Scene:
    """A copy whose sensor-noise seed (dynamic or static scene) is ``seed`` (None: unchanged)."""
    if seed is None:
        return scene
    if scene.sim is not None:
        return replace(scene, sim=replace(scene.sim, sensors=replace(scene.sim.sensors, seed=seed)))
    if scene.static is not None:
        return replace(scene, static=replace(scene.static, sensors=replace(scene.static.sensors, seed=seed)))
    return scene


def with_overrides(scene: Scene, **kw) -> Scene:
    """A copy with SimConfig fields replaced (integrator, duration_s, seed via sensors...)."""
    if scene.sim is None:
        return scene
    return replace(scene, sim=replace(scene.sim, **kw))
