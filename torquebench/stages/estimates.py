"""The estimator on the scene's readings and its errors: measured against the truth, predicted by
Monte Carlo for the same sensor and posture.

    estimates           readings, torques        → estimates (observer + localizer, per method)
    localization_error  estimates, truth         → localization_error (collision-phase scores)
    predicted_error     chain, calibration, truth → predicted_error (Monte Carlo, same sensor/posture)
"""

from __future__ import annotations

import math

import numpy as np

from torquebench.stages.cachekey import canon
from torquebench.stages.declaration import Stage
from torquebench.stages.noise import _torque_from_counts, scene_noise_model
from torquebench.stages.scoring import METHODS, collision_phase_errors
from userio.errors import InputError


def run_estimates(scene, inp, seed=None):
    """Observer + detector + localizer per method. The detector knows the scene's sensor noise
    (scene_noise_model): ``dynamic`` without [estimator].threshold → chi-square at
    [estimator].false_alarm_rate; ``paper`` → ε = 0.06 (or the threshold), its isolation rows
    whitened by the same noise model. A scene that sets threshold gets ‖r‖ > threshold for both."""
    from estimator.log import SensorLog
    from estimator.estimate import estimate

    rd, tq = inp["readings"], inp["torques"]
    robot = scene.robot                 # the file the estimator reads (the simulation: sim.robot)
    tau = tq["tau_Nm"]
    keep = np.all(np.isfinite(tau), axis=1)             # flagged samples stay out of detection
    log = SensorLog(t=rd["t"][keep], q=rd["q"][keep], dq=rd["dq"][keep], tau_Nm=tau[keep],
                    wrench=rd["wrench"][keep], floating=rd["floating"], source=str(scene.path))
    e = scene.estimator
    quiet = {}
    if e.quiet_window_s is not None:      # the stretch states the noise, not the scene's sensors
        noise = None
        quiet = {"quiet_window": e.quiet_window_s,
                 "quiet_where": f"{scene.path}: estimator.quiet_window_s"}
        source = "robust estimate over the quiet window {:g}–{:g} s".format(*e.quiet_window_s)
    else:
        try:
            noise = scene_noise_model(scene, inp.get("chain"), inp.get("calibration"))
        except InputError:
            if e.threshold is None:
                raise
            noise = None                  # the scene's own ε: the paper rule, as before
        source = noise.describe() if noise is not None else None
    out = {"kept": keep, "flagged_samples": int((~keep).sum()), "noise_source": source}
    for m in METHODS:
        out[m] = estimate(robot, log, method=m, gain_per_s=e.gain_per_s, threshold=e.threshold,
                          noise=noise, false_alarm_rate=e.false_alarm_rate, **quiet)
    return out


def _truth_rows(truth, keep):
    return {k: np.asarray(v)[keep] for k, v in truth.items()}


def run_localization_error(scene, inp, seed=None):
    est, tr = inp["estimates"], inp["truth"]
    truth = _truth_rows(tr["truth"], est["kept"])
    out = {"flagged_samples": est["flagged_samples"]}
    for m in METHODS:
        out[m] = collision_phase_errors(est[m], truth, scene.sim.pokes, scene.estimator.gain_per_s)
    return out


def run_predicted_error(scene, inp, seed=None, draws=2000):
    """Monte Carlo (estimator.uncertainty) at the mean posture of the collision phase, with the
    chain's σ_τ, the calibration's relative slope uncertainty and the robot file's parameter
    uncertainty (its identification or declared [model_uncertainty]: estimator.model_error);
    MC standard error of the RMS from the draws (σ_RMS ≈ RMS·√(kurtosis-1)/(2√n) estimated by
    the delta method)."""
    from estimator.model_error import resolve
    from estimator.uncertainty import SensorNoise, monte_carlo

    chain, cal = inp["chain"], inp.get("calibration")
    gain_rel = 0.0
    if cal is not None:
        gain_rel = math.sqrt(cal.coef_cov[0, 0]) / abs(cal.coef_mean[0])
    cfg = scene.sim
    poke = cfg.pokes[0]
    tr = inp.get("truth")
    q = np.asarray(cfg.controller.q0_rad, float)
    if tr is not None:
        phase = tr["truth"]["link"] > 0
        q = tr["q"][phase, 3:].mean(axis=0)
    force = poke.magnitude_N * np.array([math.cos(poke.direction_rad), math.sin(poke.direction_rad)])
    noise = SensorNoise(torque_std_Nm=chain.noise_std_Nm, wrench_std=cfg.sensors.ft_noise,
                        torque_gain_rel_std=gain_rel, sample_rate_Hz=cfg.sensors.sample_rate_Hz,
                        gain_per_s=scene.estimator.gain_per_s)
    cov, cov_source = resolve(scene.robot)
    out = {"torque_noise_std_Nm": chain.noise_std_Nm, "gain_error_rel_std": gain_rel,
           "posture_rad": q.tolist(), "model_uncertainty_source": cov_source}
    for m in METHODS:
        mc = monte_carlo(scene.robot, q, poke.link, poke.alpha, force, noise, draws=draws, rng=0,
                         method=m, parameter_cov=cov)
        rms = float(mc.position_rms_m[0])
        out[m] = {"position_rms_m": rms, "position_p95_m": float(mc.position_p95_m[0]),
                  "position_rms_m_error_estimate": rms / math.sqrt(2 * draws),
                  "position_rms_m_error_method": f"Monte Carlo standard error, {draws} draws "
                                                 "(Gaussian approximation rms/√(2n), 1σ)"}
    return out



def _estimator_params(scene, seed):
    return {"est": canon(scene.estimator), "poke": canon(scene.sim.pokes if scene.sim else None),
            "robot": canon(scene.robot)}        # the file the estimator reads


def _no_poke(scene, without_sim):
    if scene.sim is None:
        return without_sim
    return None if scene.sim.pokes else "no poke in the scene"


STAGES = (
    Stage("estimates", "estimates", "momentum observer + detector (at the scene's sensor noise) + localizer",
          run_estimates, needs=("readings", "torques", "chain?", "calibration?"),
          reads=("estimator", "poke", "robot"), params=_estimator_params,
          feasible=lambda scene: None if scene.chain.log_file is not None or scene.sim is not None
          else "no source",
          uses=lambda scene, art: art not in ("chain", "calibration") or _torque_from_counts(scene),
          scene_output=True),
    Stage("localization_error", "localization_error", "errors against the truth over the collision phase",
          run_localization_error, needs=("estimates", "truth"), reads=("estimator", "poke", "robot"),
          params=_estimator_params,
          feasible=lambda scene: _no_poke(scene, "no simulation (a recorded log has no truth)"
                                          if scene.chain.log_file else "not a dynamic scene"),
          scene_output=True),
    Stage("predicted_error", "predicted_error", "Monte Carlo localization error for this sensor and posture",
          run_predicted_error, needs=("chain", "calibration?", "truth?"),
          reads=("estimator", "poke", "robot", "sensors"),
          params=lambda scene, seed: {**_estimator_params(scene, seed),   # + the FT noise, rate
                                      "sensors": canon(scene.sim.sensors if scene.sim else None)},
          feasible=lambda scene: _no_poke(scene, "the prediction needs the scene's contact (a simulated poke)"),
          scene_output=True),
)
