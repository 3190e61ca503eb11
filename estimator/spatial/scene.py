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

from userio.errors import InputError


@dataclass
class SpatialScene:
    name: str
    robot: object
    spec: object
    path: Path
    robot_kind = "spatial"          # the stage graph plans the 3-D stages for it (torquebench.stages)


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
    """A 3-D scene validated by its schema (userio.schema.spatial_scene.SpatialSceneFile); its
    vectors sized by the robot's joints and its pokes placed on the robot's link surfaces."""
    from estimator.spatial.geometry import body_surfaces
    from estimator.spatial.logs import make_noise
    from estimator.spatial.robot import load_spatial_robot, robot_from_urdf
    from estimator.spatial.sim import Poke, SimSpec
    from estimator.spatial.tree import body_poses, tree_from_model
    from userio.errors import nearest
    from userio.files import read_toml
    from userio.schema import parse
    from userio.schema.spatial_scene import SpatialSceneFile

    path = Path(path)
    d = parse(SpatialSceneFile, _apply_overrides(read_toml(path), overrides, path), path)
    err = lambda key, msg: InputError(f"{path}: {key}: {msg}")        # noqa: E731
    if isinstance(d.robot, str):
        p = _resolve(path, d.robot)
        if p is None:
            raise err("robot", f"file {d.robot!r} not found beside the scene or in robots/")
        robot = load_spatial_robot(p)
    else:
        urdf = _resolve(path, d.robot.urdf)
        if urdf is None:
            raise err("robot.urdf", f"file {d.robot.urdf!r} not found beside the scene")
        robot = robot_from_urdf(urdf)
    if d.base is not None:
        robot = robot.with_base(d.base == "floating")
    n = robot.n_joints
    ctl = d.controller

    def per_joint(key):
        v = getattr(ctl, key)
        if v is not None and len(v) != n:
            raise err(f"controller.{key}", f"expected {n} numbers (one per joint), got {len(v)}")
        return np.zeros(n) if v is None else np.asarray(v, float)

    q0, amplitude = per_joint("q0_rad"), per_joint("amplitude_rad")
    tree = tree_from_model(robot.model)
    surfaces = body_surfaces(robot, tree)
    rest = robot.rest_q()
    rest[7:] = q0
    R_bodies = body_poses(tree, rest[None])[0][0]
    pokes = []
    for i, pk in enumerate(d.poke, start=1):
        link = pk.link
        owner = [s for s in surfaces if link == s.name or link in [n_ for n_, _ in s.solids]]
        if not owner:
            names = sorted({s.name for s in surfaces} | {n_ for s in surfaces for n_, _ in s.solids})
            raise err(f"poke[{i}].link", f"no link '{link}' in {robot.source}{nearest(link, names)}")
        surf = owner[0]
        fr = robot.model.frames[robot.model.getFrameId(link)]
        R_lb, p_lb = np.array(fr.placement.rotation), np.array(fr.placement.translation)
        if pk.point_m is not None:
            p_link, normal_body = np.asarray(pk.point_m, float), None
        else:
            p_body, normal_body = surface_point(surf, link, pk.along, pk.around_rad)
            p_link = R_lb.T @ (p_body - p_lb)
        if pk.force_N is not None:
            F = np.asarray(pk.force_N, float)
        else:
            F = -pk.magnitude_N * (R_bodies[surf.body] @ normal_body)   # into the surface at q0
        pokes.append(Poke(link, p_link, F, pk.t_on_s, pk.t_off_s, pk.ramp_s))
    sens = d.sensors
    noise = None
    if sens.torque_noise_Nm is not None or sens.ft_noise is not None:
        noise = make_noise(0.005 if sens.torque_noise_Nm is None else sens.torque_noise_Nm,
                           [0.1, 0.01] if sens.ft_noise is None else sens.ft_noise,
                           int(sum(robot.sensed)), source=f"{path}: sensors")
    spec = SimSpec(duration_s=d.duration_s, sample_rate_Hz=sens.sample_rate_Hz,
                   substeps=d.integrator.substeps, q0_rad=q0, kp=ctl.kp, kd=ctl.kd,
                   amplitude_rad=amplitude, frequency_Hz=ctl.frequency_Hz, pokes=pokes, noise=noise,
                   seed=sens.seed)
    return SpatialScene(name=d.name or path.stem, robot=robot, spec=spec, path=path)


def surface_point(surface, link, along, around):
    from estimator.spatial.geometry import surface_point as sp

    return sp(surface, link, along, around)
