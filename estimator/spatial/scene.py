"""A 3-D scene (input of ``simulate`` for a URDF robot): the robot declaration, the controller,
pokes on link surfaces, the sensors. docs/conventions.md, "3-D scene TOML"::

    name = "leg_pokes"
    robot = "../robots/quadruped_leg.toml"    # a declaration or a bare URDF, relative to this file
    base = "floating"                          # optional: overrides the declaration
    duration_s = 1.2
    [controller]  q0_rad = [0.2, 0.6, -1.2], kp = 60.0, kd = 1.5, amplitude_rad = [...], frequency_Hz = 1.0
    [[poke]]      link = "shank", along = 0.4, around_rad = 0.5   # or point_m = [x, y, z] (link frame)
                  magnitude_N = 5.0                                 # into the surface; or force_N = [fx, fy, fz] (world)
                  t_on_s = 0.3, t_off_s = 0.6, ramp_s = 0.0
    [sensors]     sample_rate_Hz = 1000.0, torque_noise_Nm = 0.005, ft_noise = [0.1, 0.01], seed = 1
    [integrator]  substeps = 10
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from estimator.errors import InputError


@dataclass
class SpatialScene:
    name: str
    robot: object
    spec: object
    path: Path


TOP = {"name", "description", "robot", "base", "duration_s", "controller", "poke", "sensors", "integrator"}


def is_spatial_scene(path) -> bool:
    """A scene whose robot is a URDF (directly, or through a declaration naming one)."""
    from estimator.spatial.robot import is_spatial_robot_file
    from userio.files import read_toml

    try:
        data = read_toml(path)
    except InputError:
        return False
    rob = data.get("robot")
    if isinstance(rob, dict):
        return "urdf" in rob
    if isinstance(rob, str):
        p = _resolve(Path(path), rob)
        return p is not None and is_spatial_robot_file(p)
    return False


def _resolve(scene_path: Path, name: str) -> Path | None:
    """``name`` beside the scene, else in a ``robots/`` directory beside one of its parents, else
    in the repository's ``robots/`` (as the planar scenes find theirs)."""
    cands = ([scene_path.parent / name] + [d / "robots" / name for d in scene_path.resolve().parents]
             + [Path(__file__).resolve().parents[2] / "robots" / name])
    for cand in cands:
        if cand.is_file():
            return cand
    return None


def _apply_overrides(data: dict, overrides: dict | None, path) -> dict:
    """Dotted keys (``sensors.torque_noise_Nm``) set in the scene's TOML data before it is read;
    ``poke.2.magnitude_N`` addresses the second [[poke]]."""
    import copy

    data = copy.deepcopy(data)
    for key, value in (overrides or {}).items():
        parts = str(key).split(".")
        node = data
        for i, part in enumerate(parts[:-1]):
            if isinstance(node, list):
                try:
                    node = node[int(part) - 1]
                except (ValueError, IndexError):
                    raise InputError(f"{path}: {key}: no item {part} of {'.'.join(parts[:i])}") from None
            else:
                node = node.setdefault(part, {})
        if not isinstance(node, dict):
            raise InputError(f"{path}: {key}: not a table key")
        node[parts[-1]] = value
    return data


def load_spatial_scene(path, overrides: dict | None = None) -> SpatialScene:
    from estimator.spatial.geometry import body_surfaces
    from estimator.spatial.logs import make_noise
    from estimator.spatial.robot import load_spatial_robot, robot_from_urdf
    from estimator.spatial.sim import Poke, SimSpec
    from estimator.spatial.tree import body_poses, tree_from_model
    from userio.fields import Fields
    from userio.files import read_toml

    path = Path(path)
    data = _apply_overrides(read_toml(path), overrides, path)
    f = Fields(path)
    f.known(data, TOP, "")
    rob = data.get("robot")
    if isinstance(rob, dict):
        f.known(rob, {"urdf"}, "robot")
        urdf = _resolve(path, f.string(rob, "urdf", "robot"))
        if urdf is None:
            raise f.err("robot.urdf", f"file {rob['urdf']!r} not found beside the scene")
        robot = robot_from_urdf(urdf)
    else:
        p = _resolve(path, f.string(data, "robot", ""))
        if p is None:
            raise f.err("robot", f"file {data['robot']!r} not found beside the scene or in robots/")
        robot = load_spatial_robot(p)
    if "base" in data:
        robot = robot.with_base(f.choice(data, "base", "", ("floating", "fixed"), "floating") == "floating")
    n = robot.n_joints
    ctl = f.table(data, "controller", "")
    f.known(ctl, {"q0_rad", "kp", "kd", "amplitude_rad", "frequency_Hz"}, "controller")
    sens = f.table(data, "sensors", "")
    f.known(sens, {"sample_rate_Hz", "torque_noise_Nm", "ft_noise", "seed"}, "sensors")
    integ = f.table(data, "integrator", "")
    f.known(integ, {"substeps"}, "integrator")
    q0 = f.vector(ctl, "q0_rad", "controller", n, [0.0] * n)
    tree = tree_from_model(robot.model)
    surfaces = body_surfaces(robot, tree)
    rest = robot.rest_q()
    rest[7:] = q0
    R_bodies = body_poses(tree, rest[None])[0][0]
    pokes = []
    for i, pk in enumerate(data.get("poke", []) or []):
        where = f"poke[{i + 1}]"
        if not isinstance(pk, dict):
            raise f.err(where, "expected a table")
        f.known(pk, {"link", "point_m", "along", "around_rad", "force_N", "magnitude_N", "t_on_s",
                     "t_off_s", "ramp_s"}, where)
        link = f.string(pk, "link", where)
        owner = [s for s in surfaces if link == s.name or link in [n_ for n_, _ in s.solids]]
        if not owner:
            from userio.fields import nearest

            names = sorted({s.name for s in surfaces} | {n_ for s in surfaces for n_, _ in s.solids})
            raise f.err(f"{where}.link", f"no link '{link}' in {robot.source}{nearest(link, names)}")
        surf = owner[0]
        fr = robot.model.frames[robot.model.getFrameId(link)]
        R_lb, p_lb = np.array(fr.placement.rotation), np.array(fr.placement.translation)
        if "point_m" in pk:
            p_link = f.vector(pk, "point_m", where, 3)
            normal_body = None
        else:
            p_body, normal_body = surface_point(surf, link, f.number(pk, "along", where, 0.5, lo=0.0, hi=1.0),
                                                f.number(pk, "around_rad", where, 0.0))
            p_link = R_lb.T @ (p_body - p_lb)
        if "force_N" in pk:
            F = f.vector(pk, "force_N", where, 3)
        else:
            if normal_body is None:
                raise f.err(f"{where}.magnitude_N", "with point_m give force_N (world), or use along/around_rad")
            mag = f.number(pk, "magnitude_N", where, positive=True)
            F = -mag * (R_bodies[surf.body] @ normal_body)         # into the surface at q0
        t_on = f.number(pk, "t_on_s", where, nonneg=True)
        t_off = f.number(pk, "t_off_s", where, positive=True)
        if t_off <= t_on:
            raise f.err(f"{where}.t_off_s", f"must be after t_on_s = {t_on:g} s")
        pokes.append(Poke(link, p_link, F, t_on, t_off, f.number(pk, "ramp_s", where, 0.0, nonneg=True)))
    noise = None
    if "torque_noise_Nm" in sens or "ft_noise" in sens:
        noise = make_noise(f.number(sens, "torque_noise_Nm", "sensors", 0.005, positive=True),
                           f.vector(sens, "ft_noise", "sensors", None, [0.1, 0.01], positive=True),
                           int(sum(robot.sensed)), source=f"{path}: sensors")
    spec = SimSpec(duration_s=f.number(data, "duration_s", "", 1.0, positive=True, hi=3600.0),
                   sample_rate_Hz=f.number(sens, "sample_rate_Hz", "sensors", 1000.0, positive=True, hi=1e5),
                   substeps=f.integer(integ, "substeps", "integrator", 10, lo=1, hi=1000),
                   q0_rad=q0, kp=f.number(ctl, "kp", "controller", 60.0, nonneg=True),
                   kd=f.number(ctl, "kd", "controller", 1.5, nonneg=True),
                   amplitude_rad=f.vector(ctl, "amplitude_rad", "controller", n, [0.0] * n),
                   frequency_Hz=f.number(ctl, "frequency_Hz", "controller", 1.0, nonneg=True),
                   pokes=pokes, noise=noise, seed=f.integer(sens, "seed", "sensors", 0, lo=0))
    return SpatialScene(name=f.string(data, "name", "", path.stem), robot=robot, spec=spec, path=path)


def surface_point(surface, link, along, around):
    from estimator.spatial.geometry import surface_point as sp

    return sp(surface, link, along, around)
