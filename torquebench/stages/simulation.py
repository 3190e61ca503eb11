"""The robot's side: the noise-free simulation, the sensors' readings of it, and static holds.

    simulation     scene's robot/controller/poke → truth (noise-free run: q, q̇, τ, W, contact)
    raw_counts     truth, chain, seed          → readings (joint torques as ADC counts, FT noise;
                                                 or a recorded log and its counts columns)
    sensor_log     truth, chain (bridge model) → log (the simulator's own sensor model: `simulate`)
    static_holds   the static scene's holds    → static_log (Table IV / posture sweep equilibria)
"""

from __future__ import annotations

import math
import time

import numpy as np

from torquebench.stages.cachekey import canon, file_hash
from torquebench.stages.declaration import Stage
from torquebench.stages.noise import scene_noise_model
from torquebench.stages.sensor import adc_bits
from userio.errors import InputError

TARE_S = 0.3          # no-load hold before static loads: the estimator's noise floors come from it

def _quiet(cfg):
    """The scene's SimConfig with noise-free sensors at its sample rate (the integration reads
    only the rate; every sensor model is applied to the sampled truth afterwards)."""
    from dataclasses import replace

    from estimator.sim.config import Sensors

    quiet = Sensors(sample_rate_Hz=cfg.sensors.sample_rate_Hz, torque_model="gaussian",
                    torque_noise_Nm=0.0, ft_noise=[0.0, 0.0, 0.0], seed=0)
    return replace(cfg, sensors=quiet)


def run_simulation(scene, inp, seed=None):
    """Noise-free run (sensor noise is drawn by raw_counts or sensor_log, so seeds reuse this
    stage); refused before integrating when predicted to take longer than scene.max_run_time_s."""
    from estimator.sim import simulate

    cfg = scene.sim
    res = simulate(_quiet(cfg), max_run_time_s=scene.max_run_time_s)
    return {"t": res.t, "q": res.q, "dq": res.dq, "tau_Nm": res.tau_Nm, "wrench": res.wrench,
            "truth": res.truth, "floating": cfg.base == "floating", "stats": res.stats}


def run_raw_counts(scene, inp, seed):
    """Joint torques as ADC codes of the real sensor (true gain × model), FT and encoder noise
    through estimator.sim.sensors.measure; codes at the rails are flagged (kept, never clipped
    silently into a torque)."""
    import warnings
    from dataclasses import replace

    from bridge.chain import ADCSaturationWarning
    from estimator.sim.sensors import measure

    if scene.chain.log_file is not None:
        return _read_counts_log(scene)
    tr, chain = inp["truth"], inp["chain"]
    sensors = replace(scene.sim.sensors, seed=seed, torque_model="gaussian", torque_noise_Nm=0.0)
    q, dq, _, W = measure(sensors, tr["q"], tr["dq"], tr["tau_Nm"], tr["wrench"], 3)
    true_chain = replace(chain, strain_per_Nm=chain.strain_per_Nm * scene.chain.true_gain_factor)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ADCSaturationWarning)
        codes = true_chain.counts(tr["tau_Nm"], np.random.default_rng([seed, 7]))
    if not tr["floating"]:
        q[:, :3] = dq[:, :3] = 0.0
    return {"t": tr["t"], "q": q, "dq": dq, "counts": codes, "wrench": W, "floating": tr["floating"],
            "rails": chain.code_limits}


def _read_counts_log(scene):
    """A recorded log; with counts columns, those are read here (pandas), torques come later."""
    import pandas as pd

    from estimator.log_reader import read_log

    c = scene.chain
    log = read_log(c.log_file, scene.robot)
    out = {"t": log.t, "q": log.q, "dq": log.dq, "wrench": log.wrench, "floating": log.floating,
           "tau_Nm": log.tau_Nm}
    if c.counts_columns:
        frame = pd.read_csv(c.log_file, comment="#")
        missing = [k for k in c.counts_columns if k not in frame.columns]
        if missing:
            raise InputError(f"{c.log_file}: column {missing[0]!r} (source.counts_columns) not in the log")
        codes = frame[list(c.counts_columns)].to_numpy(float)
        if log.valid_mask is not None:
            codes = codes[log.valid_mask]
        out["counts"] = codes
        if c.reading_unit == "counts":                    # ADC codes: the rails are flagged
            from bridge.adc import code_limits
            out["rails"] = code_limits(adc_bits(scene))
        else:                                             # mV readings: only non-finite ones
            out["rails"] = (-math.inf, math.inf)
    return out



def run_sensor_log(scene, inp, seed=None):
    """The log `simulate` writes: estimator.sim.sensors.measure(scene sensors, sampled truth) —
    encoders, gaussian or bridge/ADC torque (through the scene's one sensor chain), FT noise;
    a fixed or rigid base logs zero base columns. Returns {log, truth, stats, noise}: ``noise``
    is the NoiseModel the sensors drew (scene_noise_model, readings="log"), which `simulate`
    declares beside the log, or None when a channel is noise-free (nothing to whiten with)."""
    from estimator.log import SensorLog
    from estimator.sim.sensors import measure

    cfg, tr = scene.sim, inp["truth"]
    chain = inp.get("chain") if cfg.sensors.torque_model == "bridge" else None
    q, dq, tau, W = measure(cfg.sensors, tr["q"], tr["dq"], tr["tau_Nm"], tr["wrench"], 3, chain=chain)
    if cfg.base != "floating":
        q[:, :3] = 0.0
        dq[:, :3] = 0.0
    log = SensorLog(t=tr["t"], q=q, dq=dq, tau_Nm=tau, wrench=W, floating=cfg.base == "floating")
    try:
        noise = scene_noise_model(scene, chain, readings="log")
    except InputError:                    # a zero σ: a noise-free channel declares nothing
        noise = None
    return {"log": log, "truth": tr["truth"], "stats": tr["stats"], "noise": noise}


def run_static_holds(scene, inp, seed=None):
    """Static equilibria (estimator.sim.static.static_hold_log): every point held for hold_s
    after a TARE_S no-load tare. Returns {log, truth, index (the point of each sample, −1 in
    the tare), stats}."""
    from estimator.sim.static import static_hold_log

    st = scene.static
    start = time.perf_counter()
    pts = st.points
    log, truth, index = static_hold_log(st.robot, np.array([p.q_rad for p in pts]),
                                    np.array([p.link for p in pts]), np.array([p.alpha for p in pts]),
                                    np.array([p.force_N for p in pts]), st.sensors, st.hold_s,
                                    tare_s=TARE_S)
    return {"log": log, "truth": truth, "index": index,
            "stats": {"integrator": "static", "run_time_s": time.perf_counter() - start,
                      "points": len(pts)}}



def _no_truth(scene):
    if scene.sim is None:
        return "no simulation (a recorded log has no truth)" if scene.chain.log_file else "not a dynamic scene"
    return None


def _log_given(scene):
    f = scene.chain.log_file
    return f"recorded log {f.name} given" if f is not None else None


def _counts_params(scene, seed):
    c = scene.chain
    return {"gain": c.true_gain_factor, "seed": seed, "log": file_hash(c.log_file),
            "cols": c.counts_columns, "unit": c.reading_unit, "ft": canon(getattr(scene.sim, "sensors", None))}


STAGES = (
    Stage("simulation", "truth", "noise-free robot simulation", run_simulation,
          reads=("robot", "controller", "poke", "sensors.sample_rate_Hz"),
          params=lambda scene, seed: {"sim": canon(_quiet(scene.sim))},   # noise-free: not the noise
          feasible=_no_truth, given=_log_given),
    Stage("raw_counts", "readings", "joint torques as raw ADC counts + FT noise", run_raw_counts,
          needs=("truth", "chain"), reads=("sensor.true_gain_factor", "source", "sensors"),
          params=_counts_params,
          feasible=lambda scene: None if scene.chain.log_file is not None or scene.sim is not None
          else "no source",
          uses=lambda scene, art: art != "truth" or scene.chain.log_file is None),
    Stage("sensor_log", "log", "the simulator's sensor model on the truth (the log `simulate` writes)",
          run_sensor_log, needs=("truth", "chain?"), reads=("sensors", "base"),
          params=lambda scene, seed: {"sensors": canon(scene.sim.sensors), "base": scene.sim.base},
          feasible=lambda scene: None if scene.sim is not None else "not a dynamic simulation" + (
              " (a recorded log is read as it is)" if scene.chain.log_file else ""),
          uses=lambda scene, art: art != "chain" or scene.sim.sensors.torque_model == "bridge"),
    Stage("static_holds", "static_log", "static equilibrium holds of a static scene", run_static_holds,
          reads=("static",), params=lambda scene, seed: {"static": canon(scene.static)},
          feasible=lambda scene: None if scene.static is not None else
          "not a static scene (static_loading or posture_sweep)"),
)
