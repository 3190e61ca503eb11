"""Scene files (TOML) → simulation configurations, validated field by field.

Three kinds of scene:

- ``kind = "dynamic"`` (default): one time simulation (estimator.sim.SimConfig): base, controller,
  pokes, optional ground, sensors, integrator.
- ``kind = "static_loading"``: masses hung on the links of a held leg (Table IV); each load is held
  for ``hold_s`` and the static equilibrium readings (estimator.sim.static_readings) are sampled.
- ``kind = "posture_sweep"``: a grid of postures × contact points × one force, same static model.

Validated by the scene schema (userio.schema.scene; every field in docs/inputs.md); every error
is a userio.errors.InputError naming the file and the field.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from estimator.robot import Robot, load_robot
from estimator.sim.config import Controller, Ground, Poke, Sensors, SimConfig
from estimator.limits import ALPHA_RANGE, FORCE_RANGE, GAIN_RANGE, SAMPLE_RATE_RANGE, THRESHOLD_RANGE
from estimator.noise import FT_SIGMA_RANGE, TORQUE_SIGMA_RANGE
from userio.errors import InputError
from torquebench.io import REPO_ROOT
from userio.errors import nearest
from userio.ranges import Range, ranged
from userio.files import read_toml

G_M_PER_S2 = 9.81


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


def _find(path: Path, name: str, shipped: str) -> Path | None:
    """A file a scene names: beside the scene, else in the repository's ``shipped`` folder."""
    for cand in (path.parent / name, REPO_ROOT / shipped / name, Path(name)):
        if cand.is_file():
            return cand
    return None


def _file(path: Path, name: str | None, where: str, shipped: str) -> Path | None:
    if name is None:
        return None
    found = _find(path, name, shipped)
    if found is None:
        raise InputError(f"{path}: {where}: file {name!r} not found beside the scene or in {shipped}/")
    return found


def _robot_file(path: Path, name: str, where: str) -> tuple[Robot, Path]:
    found = _file(path, name, where, "robots")
    try:
        return load_robot(found), found
    except InputError as exc:
        raise InputError(f"{path}: {where}: {exc}") from None


def _true_robot(path: Path, ref, robot: Robot) -> Robot:
    """The robot the simulator simulates: the file's, or (a dynamic scene's [robot] table)
    ``true_parameters = "other.toml"`` (same links, other inertial data) or a ``perturbation``
    (relative 1σ of masses, inertias and, × link length, centres of mass; drawn with
    ``perturbation_seed``, estimator.inertial.perturbed)."""
    from estimator.inertial import perturbed
    from estimator.model import ModelUncertainty

    if ref is None or (ref.true_parameters is None and ref.perturbation is None):
        return robot
    if ref.true_parameters is not None:
        true, _ = _robot_file(path, ref.true_parameters, "robot.true_parameters")
        if true.n_links != robot.n_links or not np.allclose(true.lengths_m, robot.lengths_m):
            raise InputError(f"{path}: robot.true_parameters: {true.name} has links "
                             f"{true.lengths_m.tolist()} m, the file {robot.name} "
                             f"{robot.lengths_m.tolist()} m: only inertial data may differ")
        return replace(true, floating=robot.floating)
    rel = ref.perturbation
    seed = ref.perturbation_seed or 0
    return perturbed(robot, ModelUncertainty.uniform(rel), seed) if rel > 0 else robot


def _sensors(d) -> Sensors:
    t = d.sensors
    return Sensors(sample_rate_Hz=t.sample_rate_Hz, torque_model=t.torque_model,
                   torque_noise_Nm=0.01 if t.torque_noise_Nm is None else t.torque_noise_Nm,
                   ft_noise=np.asarray(t.ft_noise, float), encoder_counts=t.encoder_counts,
                   velocity_noise_rad_per_s=t.velocity_noise_rad_per_s, seed=t.seed)


def _estimator(d) -> EstimatorSettings:
    from estimator.noise import parse_rate

    t = d.estimator
    return EstimatorSettings(method=t.method, gain_per_s=t.gain_per_s, threshold=t.threshold,
                             false_alarm_rate=parse_rate(str(t.false_alarm_rate)),
                             quiet_window_s=None if t.quiet_window_s is None
                             else tuple(float(x) for x in t.quiet_window_s))


def _per_joint(path: Path, where: str, v, n: int) -> np.ndarray:
    arr = np.asarray(v, float)
    if arr.shape[0] != n:
        raise InputError(f"{path}: {where}: expected {n} values (one per joint), got {arr.shape[0]}")
    return arr


def _link(path: Path, where: str, link: int, n: int) -> int:
    if not 1 <= link <= n:
        raise InputError(f"{path}: {where}: expected an integer in 1..{n}, got {link!r}")
    return link


def _dynamic(path: Path, d, robot: Robot, name: str) -> SimConfig:
    n = robot.n_links
    c = d.controller
    traj = {}
    if any(getattr(c, k) is not None for k in ("amplitude_rad", "frequency_Hz", "phase_rad")):
        parts = {}
        for k in ("amplitude_rad", "frequency_Hz", "phase_rad"):
            v = getattr(c, k)
            if v is None and k != "phase_rad":
                raise InputError(f"{path}: controller.{k}: missing field (a trajectory needs "
                                 "amplitude_rad and frequency_Hz)")
            parts[k] = None if v is None else _per_joint(path, f"controller.{k}", v, n)
        shape = parts["amplitude_rad"].shape
        parts["phase_rad"] = np.zeros(shape) if parts["phase_rad"] is None else parts["phase_rad"]
        for k in ("frequency_Hz", "phase_rad"):
            if parts[k].shape != shape:
                raise InputError(f"{path}: controller.{k}: expected the shape of amplitude_rad "
                                 f"{list(shape)}, got {list(parts[k].shape)}")
        traj = parts
    controller = Controller(q0_rad=_per_joint(path, "controller.q0_rad", c.q0_rad, n), kp=c.kp,
                            kd=c.kd, mode=c.mode, rate_Hz=c.rate_Hz,
                            gravity_compensation=c.gravity_compensation, **traj)
    pokes = []
    for i, p in enumerate(d.poke, start=1):
        _link(path, f"poke[{i}].link", p.link, n)
        if p.t_off_s is not None and p.t_off_s > d.duration_s:
            import warnings

            from estimator.plausibility import PlausibilityWarning

            warnings.warn(f"{path}: poke[{i}].t_off_s = {p.t_off_s:g} s is after the end of the simulation "
                          f"(duration_s = {d.duration_s:g} s): the poke acts to the end (leave t_off_s "
                          "out for that; a time in ms?)", PlausibilityWarning, stacklevel=2)
        if p.mass_kg is not None:
            mag, direction = p.mass_kg * G_M_PER_S2, -math.pi / 2
        else:
            mag, direction = p.magnitude_N, p.direction_rad
        pokes.append(Poke(link=p.link, alpha=p.alpha, magnitude_N=mag, direction_rad=direction,
                          t_on_s=p.t_on_s, t_off_s=d.duration_s if p.t_off_s is None else p.t_off_s,
                          ramp_s=p.ramp_s))
    g = d.ground
    ground = None if g is None else Ground(
        height_m=g.height_m, stiffness_N_per_m=g.stiffness_N_per_m,
        damping_Ns_per_m=g.damping_Ns_per_m,
        tangential_stiffness_N_per_m=g.tangential_stiffness_N_per_m,
        friction_coefficient=robot.friction_coefficient if g.friction_coefficient is None
        else g.friction_coefficient)
    it, m = d.integrator, d.mount
    return SimConfig(
        robot=robot, controller=controller, base=d.base, duration_s=d.duration_s,
        pokes=tuple(pokes), ground=ground, sensors=_sensors(d), integrator=it.method,
        rtol=it.rtol, atol=it.atol, fixed_step_s=it.fixed_step_s,
        mount_stiffness=None if m is None else np.asarray(m.stiffness, float),
        mount_damping=None if m is None else np.asarray(m.damping, float), name=name)


def _static(path: Path, d, robot: Robot, name: str) -> StaticScene:
    n = robot.n_links
    points, shape = [], ()
    if d.kind == "static_loading":
        q = _per_joint(path, "q_rad", d.q_rad, n)
        for i, ld in enumerate(d.load, start=1):
            link = _link(path, f"load[{i}].link", ld.link, n)
            for mass in ld.mass_kg:
                for a in ld.alpha:
                    points.append(StaticPoint(q, link, float(a), np.array([0.0, -mass * G_M_PER_S2]),
                                              f"link {link}, {mass * 1000:g} g"))
    else:
        if n != 2:
            raise InputError(f"{path}: grid: the posture sweep is defined for 2 links, robot has {n}")
        c, count = d.contact, d.grid.count
        links = np.asarray(c.links, float)
        if np.any((links < 1) | (links > n) | (links != np.round(links))):
            raise InputError(f"{path}: contact.links: expected link numbers in 1..{n}, got "
                             f"{links.tolist()}")
        F = c.magnitude_N * np.array([math.cos(c.direction_rad), math.sin(c.direction_rad)])
        q1s, q2s = np.linspace(*d.grid.q1_rad, count), np.linspace(*d.grid.q2_rad, count)
        shape = (count, count, len(links), len(c.alpha))
        for q1 in q1s:
            for q2 in q2s:
                for link in links:
                    for a in c.alpha:
                        points.append(StaticPoint(np.array([q1, q2]), int(link), float(a), F))
    return StaticScene(name=name, kind=d.kind, robot=robot.with_base(False), points=tuple(points),
                       sensors=_sensors(d), hold_s=d.hold.hold_s, window_s=d.hold.window_s,
                       grid_shape=shape)


def _chain_spec(path: Path, d) -> ChainSpec:
    fx, se, ca, so, out = d.flexure, d.sensor, d.calibration, d.source, d.outputs
    design = _file(path, fx.design, "flexure.design", "scenes")
    sensor_file = _file(path, se.file, "sensor.file", "scenes")
    cal_file = _file(path, ca.file, "calibration.file", "calibration/data")
    session = None
    if ca.session:
        session = {"masses_g": list(ca.masses_g), "lever_arm_m": ca.lever_arm_m,
                   "repeats": ca.repeats, "n_avg": ca.n_avg, "seed": ca.seed}
    log_file = _file(path, so.log, "source.log", "samples")
    cols = so.counts_columns
    if cols and cal_file is not None:
        from calibration.store import read_document

        cal_unit = read_document(cal_file).get("reading_unit")
        if cal_unit != so.reading_unit:
            raise InputError(f"{path}: calibration.file: {cal_file.name} converts readings in "
                             f"{cal_unit!r}, but source.counts_columns hold {so.reading_unit!r} "
                             "(source.reading_unit); give a calibration fitted to "
                             f"{so.reading_unit!r} readings or set source.reading_unit")
    areas, report_dir, shipped = _report_fields(path, out)
    return ChainSpec(design, fx.strain_per_Nm, sensor_file, se.true_gain_factor, cal_file, session,
                     log_file, tuple(cols), tuple(out.want), so.reading_unit, areas, report_dir,
                     shipped)


def report_areas_available() -> list[str]:
    """The report builders: every module torquebench/reports/<area>.py (not imported here)."""
    import pkgutil

    import torquebench.reports

    return sorted(i.name for i in pkgutil.iter_modules(torquebench.reports.__path__)
                  if not i.name.startswith("_"))


def _report_fields(path: Path, out):
    """[outputs] reports / dir / regenerate_shipped: which builders, and where they write."""
    err = lambda key, msg: InputError(f"{path}: outputs.{key}: {msg}")      # noqa: E731
    areas = None
    if out.reports is not None:
        known = report_areas_available()
        for a in out.reports:
            if a not in known:
                raise err("reports", f"unknown report area {a!r}{nearest(a, known)} "
                          f"(known: {', '.join(known)})")
        areas = tuple(dict.fromkeys(out.reports))
    shipped = out.regenerate_shipped
    shipped_dir = (REPO_ROOT / "reports").resolve()
    if out.dir is not None:
        report_dir = Path(out.dir)
        if shipped and report_dir.resolve() != shipped_dir:
            raise err("regenerate_shipped", f"writes the shipped {shipped_dir}; drop outputs.dir or "
                      "this flag")
    else:
        report_dir = shipped_dir if shipped else None
    if report_dir is not None and report_dir.resolve() == shipped_dir and not shipped:
        raise err("dir", f"{report_dir} is the shipped reports directory; set "
                  "outputs.regenerate_shipped = true to replace the shipped reports")
    if report_dir is not None and report_dir.exists() and not report_dir.is_dir():
        raise err("dir", f"{report_dir} exists and is not a directory")
    return areas, report_dir, shipped


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
    """Read a scene file, validated by its schema (userio.schema.scene.SceneFile; ``overrides``:
    dotted keys set before validation), then built against its robot and the files it names."""
    from userio.schema import parse
    from torquebench.stages.registry import scene_outputs
    from userio.schema.scene import WANTABLE, SceneFile

    path = Path(path)
    data = read_toml(path)                         # a regular file: not found, a directory or a device say so
    for key, value in (overrides or {}).items():
        set_key(data, key, value, path)
    d = parse(SceneFile, data, path, context={WANTABLE: scene_outputs()})   # what the stages offer
    ref = d.robot if not isinstance(d.robot, str) else None
    robot, rfile = _robot_file(path, d.robot if ref is None else ref.file, "robot")
    name = path.stem if d.name is None else d.name
    est = _estimator(d)
    chain = _chain_spec(path, d)
    if d.kind == "dynamic" and chain.log_file is not None:
        return Scene(name, d.kind, path, d.description, None, None, est, chain, robot,
                     robot_file=rfile)
    if d.kind == "dynamic":
        return Scene(name, d.kind, path, d.description,
                     _dynamic(path, d, _true_robot(path, ref, robot), name), None, est, chain,
                     robot, robot_file=rfile)
    return Scene(name, d.kind, path, d.description, None, _static(path, d, robot, name), est, chain,
                 robot, robot_file=rfile)


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
    from userio.ranges import check_ranges

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
