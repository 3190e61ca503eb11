"""The calibration: a simulated loading session, its emcee fit (or the scene's calibration file),
and the torques read from ADC counts through it.

    calibration_session  chain, [calibration]   → session (simulated 10–1000 g loading, ADC counts)
    calibration_fit      session                → calibration (emcee posterior → SensorModel)
    calibrated_torques   readings, calibration  → torques (τ̂ and σ per sample; rail samples NaN)
"""

from __future__ import annotations

import numpy as np

from torquebench.stages.cachekey import file_hash
from torquebench.stages.declaration import Stage
from torquebench.stages.sensor import adc_bits
from userio.errors import InputError


def run_calibration_session(scene, inp, seed=None):
    """Dead weights m on lever L: τ = m g L; reading = mean of n_avg ADC codes of the chain."""
    from calibration.session import G_STANDARD_M_PER_S2, Session

    s, chain = scene.chain.session, inp["chain"]
    rng = np.random.default_rng(s["seed"])
    mass = np.tile(np.asarray(s["masses_g"], float), s["repeats"])
    tau = mass * 1e-3 * G_STANDARD_M_PER_S2 * s["lever_arm_m"]
    codes = chain.counts(np.repeat(tau[:, None], s["n_avg"], axis=1), rng)
    n = mass.size
    return Session(mass_g=mass, reading=codes.mean(axis=1), direction=np.array(["load"] * n),
                   repeat=np.repeat(np.arange(s["repeats"]), len(s["masses_g"])),
                   timestamp_s=np.full(n, np.nan), lever_arm_m=s["lever_arm_m"],
                   sensor_id="simulated", reading_unit="counts", source=f"{scene.path}: calibration")


def run_calibration_fit(scene, inp, seed=None):
    from calibration.fit import fit_session
    from calibration.model import SensorModel

    bits = adc_bits(scene)
    fit = fit_session(inp["session"], "linear", seed=scene.chain.session["seed"], n_walkers=64,
                      adc_bits=bits)
    if not fit.converged:
        raise InputError(f"{scene.path}: calibration: emcee did not converge ({fit.reason})")
    k = len(fit.coef_names)
    s = fit.thinned(2000)
    return SensorModel(model="linear", coef_names=fit.coef_names, coef_mean=fit.mean[:k],
                       coef_cov=fit.cov[:k, :k], sigma=fit.sigma, samples=s[:, :k],
                       sigma_samples=np.exp(s[:, -1]), lever_arm_m=inp["session"].lever_arm_m,
                       reading_unit="counts", sensor_id="simulated", adc_bits=bits,
                       info={"n_samples": int(fit.samples.shape[0]), "tau_max": fit.tau_max})



def load_calibration(scene):
    import calibration

    return calibration.load(scene.chain.calibration_file)


def run_calibrated_torques(scene, inp, seed=None):
    """τ̂ = calibration.torque(counts − zero) per sample, σ per sample from the posterior
    covariance and the per-sample chain noise; rail samples → NaN (kept out of detection)."""
    rd, cal = inp["readings"], inp.get("calibration")
    if "counts" not in rd:
        return {"tau_Nm": rd["tau_Nm"], "tau_std_Nm": None, "flagged": np.zeros(rd["tau_Nm"].shape, bool)}
    codes = np.asarray(rd["counts"], float)
    lo, hi = rd["rails"]
    flagged = (codes <= lo) | (codes >= hi) | ~np.isfinite(codes)
    if cal is None:                                     # no calibration: the model's nominal inverse
        import warnings
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            tau = inp["chain"].torque_from_counts(codes)
        return {"tau_Nm": np.where(flagged, np.nan, tau), "tau_std_Nm": None, "flagged": flagged}
    tau = cal.torque(codes)            # m = (reading − offset)/slope, τ = m g L (zero at the offset)
    tau_std = cal.torque_std(codes, include_noise=False)
    tau = np.where(flagged, np.nan, tau)
    return {"tau_Nm": tau, "tau_std_Nm": tau_std, "flagged": flagged}



def _file_given(scene):
    f = scene.chain.calibration_file
    return f"calibration file {f.name} given" if f is not None else None


def _calibration_params(scene, seed):
    return {"cal": file_hash(scene.chain.calibration_file)}


STAGES = (
    Stage("calibration_session", "session", "simulated static loading session (ADC counts)",
          run_calibration_session, needs=("chain",), reads=("calibration.session",),
          params=lambda scene, seed: {"session": scene.chain.session},
          feasible=lambda scene: None if scene.chain.session is not None else
          "no simulated session in [calibration]",
          given=_file_given),
    Stage("calibration_fit", "calibration", "emcee fit of the loading session",
          run_calibration_fit, needs=("session",), reads=("calibration.file",),
          params=_calibration_params,
          feasible=lambda scene: None if scene.chain.session is not None
          or scene.chain.calibration_file is not None else "no [calibration] (file or simulated session)",
          given=_file_given, load=load_calibration, scene_output=True),
    Stage("calibrated_torques", "torques", "counts → torque through the fitted calibration",
          run_calibrated_torques, needs=("readings", "calibration?", "chain?"),
          reads=("calibration.file",), params=_calibration_params,
          feasible=lambda scene: None if scene.chain.log_file is not None or scene.sim is not None
          else "no source"),
)
