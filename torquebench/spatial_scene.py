"""A 3-D scene end to end (``run``, and each point of ``sweep`` / ``compare``): simulate the
URDF robot, estimate, compare with the truth, and predict the error at the poked points.

Results have the planar stage graph's keys where they mean the same thing (``measured`` /
``predicted`` → ``dynamic`` → ``position_error_rms_m`` / ``position_rms_m``, ``sensor`` →
``torque_noise_std_Nm``), so ``sweep`` and ``compare`` tabulate 3-D scenes as they do planar
ones. The work is done by the stages of torquebench.stages.spatial (planned, cached and explained
as the planar ones); this module measures and predicts, and assembles their results.
"""

from __future__ import annotations

import time

import numpy as np


def evaluate(est, truth, settle_s: float = 0.1) -> dict:
    """Measured: over the samples with a poke (truth), the located fraction on the right link
    (isolation), the RMS and median distance to the true point of those; the flagged fraction
    of the contact-free samples (more than ``settle_s`` = 10/K after a poke: before then the
    residual still carries the poke, decaying as exp(−K t))."""
    f = est.frame
    t = f.t.to_numpy()
    contact = f.contact.to_numpy().astype(bool)
    link_true = truth.link.fillna("").to_numpy().astype(str)
    on = link_true != ""
    ok = contact & on & (f.reason.to_numpy() == "ok")
    right = ok & (f.link.to_numpy().astype(str) == link_true)
    err = np.linalg.norm(f[["px", "py", "pz"]].to_numpy()[right] - truth[["px", "py", "pz"]].to_numpy()[right], axis=1)
    ends = t[np.flatnonzero(np.diff(on.astype(int)) == -1) + 1] if on.any() else np.zeros(0)
    quiet = ~on
    for e in ends:
        quiet &= ~((t >= e) & (t < e + settle_s))
    return {"contact_samples": int(on.sum()),
            "isolation_fraction": float(right.sum() / on.sum()) if on.any() else None,
            "located_fraction": float(ok.sum() / on.sum()) if on.any() else None,
            "position_error_rms_m": float(np.sqrt(np.mean(err ** 2))) if err.size else None,
            "position_error_median_m": float(np.median(err)) if err.size else None,
            "false_alarm_fraction": float(contact[quiet].mean()) if quiet.any() else None,
            "contact_free_samples": int(quiet.sum())}


def predicted(scene, model, noise) -> dict:
    """The first-order RMS error (estimator.spatial.predict) at each poke's point and force at
    the controller's set point; their mean."""
    from estimator.spatial.geometry import body_surfaces
    from estimator.spatial.noise import residual_covariance
    from estimator.spatial.predict import point_errors

    q = scene.robot.rest_q()
    q[7:] = scene.spec.q0_rad
    surfaces = body_surfaces(scene.robot, model.tree)
    R = residual_covariance(model, q[None], np.zeros((1, model.n_v)), noise, 100.0,
                            1.0 / scene.spec.sample_rate_Hz)[0]
    errs = []
    for pk in scene.spec.pokes:
        fr = scene.robot.model.frames[scene.robot.model.getFrameId(pk.link)]
        b = fr.parentJoint - 1
        p_body = np.array(fr.placement.act(np.asarray(pk.point_m, float)))
        e, _ = point_errors(model, surfaces, q, b, p_body[None], np.asarray(pk.force_N, float)[None], R)
        errs.append(float(e[0]))
    good = [e for e in errs if np.isfinite(e)]
    return {"position_rms_m": float(np.mean(good)) if good else None, "per_poke_m": errs,
            "position_rms_m_error_method": "first-order propagation at each poke's point (set-point "
                                            "posture), mean over the pokes"}


def run_scene_stages(path, overrides: dict | None = None, seed: int | None = None, cache=None,
                     force: bool = False, outputs=None) -> tuple[dict, list]:
    """(results, [(stage, action, seconds)]): the scene through the stage graph
    (torquebench.stages.spatial; ``cache`` a torquebench.cache.Cache or None), its results
    assembled as ``run --json`` and ``sweep`` read them."""
    from estimator.spatial.scene import load_spatial_scene
    from torquebench.stages.planner import execute

    t0 = time.perf_counter()
    scene = load_spatial_scene(path, overrides)
    if seed is not None:
        scene.spec.seed = int(seed)
    arts, timing = execute(scene, outputs, cache, seed, force)
    return results(scene, arts, time.perf_counter() - t0), timing


def results(scene, arts: dict, run_time_s: float) -> dict:
    """The 3-D stages' artifacts as one result (what was computed of it)."""
    noise = scene.spec.noise
    if noise is None:
        from estimator.spatial.model import UrdfModel
        from estimator.spatial.noise import default_noise

        noise = default_noise(UrdfModel(scene.robot))
    out = {"scene": scene.name, "robot": scene.robot.name,
           "sensor": {"torque_noise_std_Nm": float(noise.torque_sigma_Nm[0]),
                      "ft_noise": noise.ft_sigma.tolist()}}
    if "spatial_localization_error" in arts:
        out["measured"] = {"dynamic": arts["spatial_localization_error"]}
    if "spatial_predicted_error" in arts:
        out["predicted"] = {"dynamic": arts["spatial_predicted_error"]}
    if "spatial_estimates" in arts:
        out["intervals"] = arts["spatial_estimates"].intervals
    out["run_time_s"] = run_time_s
    return out


def run_scene(path, overrides: dict | None = None, seed: int | None = None, cache=None) -> dict:
    """Simulate, estimate, compare and predict (``run_scene_stages``), the results only."""
    return run_scene_stages(path, overrides, seed, cache)[0]
