"""The robot and simulation tables of a scene file: [robot], [sensors], [estimator], the dynamic
scene's [controller]/[[poke]]/[ground] and the static scenes' holds, each validated field by field
(an InputError naming the file and the field)."""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import numpy as np

from estimator.robot import Robot, load_robot
from estimator.sim.config import (INTEGRATORS, Controller, Ground, Poke, Sensors, SimConfig)
from torquebench.errors import InputError
from torquebench.io import REPO_ROOT
from userio.fields import Fields as _Fields
from torquebench.scene_types import G_M_PER_S2, EstimatorSettings, StaticPoint, StaticScene


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


