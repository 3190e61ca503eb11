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

import os
from dataclasses import replace
from pathlib import Path

from estimator.robot import Robot
from torquebench.errors import InputError
from torquebench.io import REPO_ROOT
from userio.fields import Fields as _Fields
from userio.files import read_toml
from torquebench.scene_chain import _chain_spec, report_areas_available  # noqa: F401  (re-exported)
from torquebench.scene_tables import _dynamic, _estimator, _resolve_robot, _robot_path, _static, _true_robot
from torquebench.scene_types import (KINDS, ChainSpec, EstimatorSettings, PredictionSpec,  # noqa: F401
                                     Scene, StaticPoint, StaticScene)


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
