"""The stages of a 3-D scene (a URDF robot: estimator.spatial), planned, cached and explained as
the planar ones are (``Stage.robot = "spatial"``: the planner offers them to 3-D scenes only):

    spatial_simulation   robot, controller, pokes, sensors, seed → spatial_log (log, truth, noise)
    spatial_estimation   spatial_log                             → spatial_estimates
    spatial_comparison   spatial_log, spatial_estimates          → spatial_localization_error
    spatial_prediction   robot, set point, pokes, sensors        → spatial_predicted_error

torquebench.spatial_scene assembles their results into what ``run`` / ``sweep`` print.
"""

from __future__ import annotations

import hashlib

from torquebench.stages.cachekey import canon, file_hash
from torquebench.stages.declaration import Stage

ROBOT_FIELDS = ("robot", "base")
SPEC_FIELDS = ("duration_s", "controller", "poke", "sensors", "integrator")


def robot_params(scene) -> dict:
    """The robot's canonical inputs: its URDF (as read, fixed joints and all), base, sensors,
    mount, gravity, collision solids (mesh files by content)."""
    r = scene.robot
    shapes = {link: [{**canon(s), "mesh": file_hash(s.mesh_path)} for s in solids]
              for link, solids in sorted(r.shapes.items())}
    return {"urdf_sha256": hashlib.sha256(r.urdf_text.encode()).hexdigest(), "floating": r.floating,
            "joints": list(r.joint_names), "sensed": list(r.sensed), "ft_frame": r.ft_frame,
            "gravity": canon(r.gravity_m_per_s2), "mount": canon([r.mount_xyz, r.mount_rpy,
                                                                r.mount_stiffness, r.mount_damping]),
            "shapes": shapes}


def simulation_params(scene, seed) -> dict:
    from dataclasses import replace

    return {"robot": robot_params(scene), "spec": canon(replace(scene.spec, seed=int(seed)))}


def prediction_params(scene, seed) -> dict:
    """What the prediction reads: the robot, the set point, the pokes, the sensors' noise and
    rate (not the seed, the duration or the trajectory's amplitude)."""
    s = scene.spec
    return {"robot": robot_params(scene), "q0_rad": canon(s.q0_rad), "pokes": canon(s.pokes),
            "noise": canon(s.noise), "sample_rate_Hz": canon(s.sample_rate_Hz)}


def estimation_params(scene, seed) -> dict:
    return {"robot": robot_params(scene)}


def run_spatial_simulation(scene, inp, seed):
    """The URDF robot on its rig (estimator.spatial.sim), sensors with the scene's noise."""
    from dataclasses import replace

    from estimator.spatial.sim import simulate

    log, truth, noise = simulate(scene.robot, replace(scene.spec, seed=int(seed)))
    return {"log": log, "truth": truth, "noise": noise}


def run_spatial_estimation(scene, inp, seed):
    """The 3-D estimator (estimator.spatial.pipeline) on the log, with the log's noise."""
    from estimator.spatial.model import UrdfModel
    from estimator.spatial.pipeline import estimate_log

    sim = inp["spatial_log"]
    return estimate_log(UrdfModel(scene.robot), [sim["log"]], 1.0 / scene.spec.sample_rate_Hz,
                        noise=sim["noise"])


def run_spatial_comparison(scene, inp, seed):
    """Measured against the truth (torquebench.spatial_scene.evaluate)."""
    from torquebench.spatial_scene import evaluate

    return evaluate(inp["spatial_estimates"], inp["spatial_log"]["truth"])


def run_spatial_prediction(scene, inp, seed):
    """The first-order error at each poke (torquebench.spatial_scene.predicted)."""
    from estimator.spatial.model import UrdfModel
    from estimator.spatial.noise import default_noise
    from torquebench.spatial_scene import predicted

    model = UrdfModel(scene.robot)
    return predicted(scene, model, scene.spec.noise or default_noise(model))


STAGES = (
    Stage("spatial_simulation", "spatial_log",
          "simulate the URDF robot on its rig: log, truth, sensor noise", run_spatial_simulation,
          reads=ROBOT_FIELDS + SPEC_FIELDS, params=simulation_params, robot="spatial"),
    Stage("spatial_estimation", "spatial_estimates",
          "the 3-D estimator on the simulated log (detection, release, localization)",
          run_spatial_estimation, needs=("spatial_log",), reads=ROBOT_FIELDS,
          params=estimation_params, robot="spatial"),
    Stage("spatial_comparison", "spatial_localization_error",
          "the estimates against the truth: isolation, position error, false alarms",
          run_spatial_comparison, needs=("spatial_log", "spatial_estimates"), robot="spatial"),
    Stage("spatial_prediction", "spatial_predicted_error",
          "first-order localization error at each poke (set-point posture)", run_spatial_prediction,
          reads=ROBOT_FIELDS + ("controller.q0_rad", "poke", "sensors"), params=prediction_params,
          robot="spatial"),
)
