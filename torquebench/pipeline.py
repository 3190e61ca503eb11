"""The whole chain in one file: every stage, what it needs, what it gives, and the graph runner.

    flexure_fem        [flexure].design           → flexure (FEM: strain per N·m, stiffness, safety)
    sensor_chain       strain per N·m, [sensor]    → chain (bridge/ADC model; sensitivity, σ_τ)
    calibration_session chain, [calibration]       → session (simulated 10–1000 g loading, ADC counts)
    calibration_fit    session                     → calibration (emcee posterior → SensorModel)
    simulation         scene's robot/controller/poke → truth (noise-free run: q, q̇, τ, W, contact)
    raw_counts         truth, chain, seed          → readings (joint torques as ADC counts, FT noise)
    calibrated_torques readings, calibration       → torques (τ̂ and σ per sample; rail samples NaN)
    estimates          torques                     → estimates (observer + localizer, per method)
    localization_error estimates, truth            → localization_error (collision-phase scores)
    predicted_error    chain, calibration, truth   → predicted_error (Monte Carlo, same sensor/posture)
    sensor_log         truth, chain (bridge model) → log (the simulator's own sensor model: `simulate`)
    static_holds       the static scene's holds    → static_log (Table IV / posture sweep equilibria)
    paper_scores       log (dynamic scenes)        → paper_scores (the reproduction's scores: `reproduce`)
    error_map          chain, calibration          → error_map (MC + first order over a posture grid:
                                                     `propagate`)
    report             what the scene computes     → report (views of the scene's own results,
                                                     torquebench.scene_views, + a summary, into
                                                     [outputs].dir)

The graph is built backwards from the requested outputs; a stage whose result the scene gives
(a ``strain_per_Nm``, a calibration file, a recorded log) is not run. Stage results are cached
on disk (torquebench.cache) under a key of the stage, its canonical inputs, its upstream keys and
the code version: this file and the source of the domain packages the stage calls (STAGE_CODE).
Heavy packages are imported inside the stage functions only.
"""

from __future__ import annotations

import functools
import hashlib
import json
import math
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from torquebench import formatting as fmt
from torquebench.scene_views import VIEWS
from userio.errors import InputError

# the code version in every cache key: this file's content (any edit to a stage invalidates) and
# the source of the packages the stage calls (STAGE_CODE, closed over PACKAGE_IMPORTS)
CODE_VERSION = hashlib.sha256(Path(__file__).read_bytes()).hexdigest()[:16]
SOURCE_ROOT = Path(__file__).resolve().parents[1]       # where bridge/, flexure/, ... sit
PACKAGE_IMPORTS = {"bridge": (), "flexure": ("bridge",), "calibration": ("bridge",),
                   "estimator": ("bridge",)}              # which domain packages import which
STAGE_CODE = {
    "flexure_fem": ("flexure",), "sensor_chain": ("bridge",),
    "calibration_session": ("calibration", "bridge"), "calibration_fit": ("calibration",),
    "simulation": ("estimator",), "raw_counts": ("estimator", "bridge"),
    "calibrated_torques": ("calibration", "bridge"), "estimates": ("estimator",),
    "localization_error": (), "predicted_error": ("estimator",),
    "sensor_log": ("estimator", "bridge"), "static_holds": ("estimator",),
    "paper_scores": ("estimator", "torquebench/reports/reproduction.py"),
    "error_map": ("estimator", "calibration"),
}
METHODS = ("dynamic", "paper")


@functools.lru_cache(maxsize=None)
def source_hash(rel: str) -> str:
    """SHA-256 of the ``*.py`` files under SOURCE_ROOT/rel (a package directory or one file):
    their relative paths and contents, in sorted order. Computed once per process."""
    root = SOURCE_ROOT / rel
    files = sorted(f for f in root.rglob("*.py") if "__pycache__" not in f.parts) if root.is_dir() \
        else [root]
    h = hashlib.sha256()
    for f in files:
        h.update(f.relative_to(SOURCE_ROOT).as_posix().encode() + b"\0" + f.read_bytes() + b"\0")
    return h.hexdigest()[:16]


def stage_code(stage: str) -> dict:
    """{package: source hash} of every package ``stage`` calls, with the packages they import."""
    todo, seen = list(STAGE_CODE.get(stage, ())), set()
    while todo:
        pkg = todo.pop()
        if pkg not in seen:
            seen.add(pkg)
            todo.extend(PACKAGE_IMPORTS.get(pkg, ()))
    return {pkg: source_hash(pkg) for pkg in sorted(seen)}


@dataclass(frozen=True)
class Stage:
    name: str
    needs: tuple          # artifact names
    gives: str            # artifact name
    doc: str


STAGES = (
    Stage("flexure_fem", (), "flexure", "tetrahedral FEM of the flexure design (three mesh levels, error estimates)"),
    Stage("sensor_chain", ("flexure?",), "chain", "bridge/amplifier/ADC model at the strain per N·m"),
    Stage("calibration_session", ("chain",), "session", "simulated static loading session (ADC counts)"),
    Stage("calibration_fit", ("session",), "calibration", "emcee fit of the loading session"),
    Stage("simulation", (), "truth", "noise-free robot simulation"),
    Stage("raw_counts", ("truth", "chain"), "readings", "joint torques as raw ADC counts + FT noise"),
    Stage("calibrated_torques", ("readings", "calibration?", "chain?"), "torques",
          "counts → torque through the fitted calibration"),
    Stage("estimates", ("readings", "torques", "chain?", "calibration?"), "estimates",
          "momentum observer + detector (at the scene's sensor noise) + localizer"),
    Stage("localization_error", ("estimates", "truth"), "localization_error",
          "errors against the truth over the collision phase"),
    Stage("predicted_error", ("chain", "calibration?", "truth?"), "predicted_error",
          "Monte Carlo localization error for this sensor and posture"),
    Stage("sensor_log", ("truth", "chain?"), "log",
          "the simulator's sensor model on the truth (the log `simulate` writes)"),
    Stage("static_holds", (), "static_log", "static equilibrium holds of a static scene"),
    Stage("paper_scores", ("log?", "chain?"), "paper_scores", "the paper reproduction's scores of the scene"),
    Stage("error_map", ("chain?", "calibration?"), "error_map",
          "Monte Carlo + first-order localization error over a posture grid"),
    Stage("report", ("chain?", "flexure?", "session?", "calibration?", "truth?", "estimates?",
                     "localization_error?", "predicted_error?", "paper_scores?"), "report",
          "views of the scene's own results (torquebench.scene_views) + its summary, into the "
          "scene's output directory"),
)
# what each report view (torquebench.scene_views.VIEWS) shows: a view is drawn only when the scene
# computes that artifact; an area of torquebench/reports with no view is not about one scene (None)
REPORT_INPUTS = {v.name: v.needs for v in VIEWS.values()}
BY_GIVES = {s.gives: s for s in STAGES}
ALIASES = {"sensitivity": "chain", "noise_budget": "chain"}
DEFAULT_OUTPUTS = ("localization_error", "predicted_error")


# ---------------------------------------------------------------- scoring (the one definition)
def collision_phase_mask(t, pokes, gain_per_s: float) -> np.ndarray:
    """The collision phase: t ∈ [t_on + ramp + 5/K, t_off) of each poke (after 5 observer time
    constants the residual is within e⁻⁵ ≈ 0.7 % of the step)."""
    t = np.asarray(t)
    phase = np.zeros(t.shape, bool)
    for p in pokes:
        if p.t_off_s > p.t_on_s:
            phase |= (t >= p.t_on_s + p.ramp_s + 5.0 / gain_per_s) & (t < p.t_off_s)
    return phase


def contact_free_mask(t, pokes, gain_per_s: float) -> np.ndarray:
    """Samples with no contact and no residual of one: outside [t_on, t_off + ramp + 10/K) of
    every poke (10 observer time constants: the residual's decay is below e⁻¹⁰ of the step)."""
    t = np.asarray(t)
    free = np.ones(t.shape, bool)
    for p in pokes:
        free &= ~((t >= p.t_on_s) & (t < p.t_off_s + p.ramp_s + 10.0 / gain_per_s))
    return free


def collision_phase_errors(est, truth, pokes, gain_per_s: float) -> dict:
    """Mean/RMS |p̂ − p| and mean |F̂ − F| over the collision phase (collision_phase_mask), over
    the samples with a finite estimate; the one scoring function of demo, run and the reports."""
    phase = collision_phase_mask(truth["t"], pokes, gain_per_s) & (truth["link"] > 0)
    ok = phase & np.isfinite(est.px)
    dp = np.hypot(est.px[ok] - truth["px"][ok], est.pz[ok] - truth["pz"][ok])
    dF = np.hypot(est.Fx[ok] - truth["Fx"][ok], est.Fz[ok] - truth["Fz"][ok])
    return {"position_error_mean_m": float(dp.mean()) if dp.size else None,
            "position_error_rms_m": float(np.sqrt(np.mean(dp ** 2))) if dp.size else None,
            "force_error_mean_N": float(dF.mean()) if dF.size else None,
            "scored_samples": int(ok.sum()), "collision_samples": int(phase.sum())}


# ---------------------------------------------------------------- what the scene gives
def given(scene, art: str) -> str | None:
    """Why artifact ``art`` need not be computed (the scene gives it), or None."""
    c = scene.chain
    if art == "flexure" and c.flexure_design is None:
        return "no [flexure].design" + (" (strain_per_Nm given)" if c.strain_per_Nm else "")
    if art in ("session", "calibration") and c.calibration_file is not None:
        return f"calibration file {c.calibration_file.name} given"
    if art == "truth" and c.log_file is not None:
        return f"recorded log {c.log_file.name} given"
    return None


def _params(scene, stage: str, seed) -> dict:
    """The canonical inputs a stage reads from the scene (part of its cache key)."""
    c = scene.chain
    if stage == "flexure_fem":
        return {"design": _design_hash(c.flexure_design)}
    if stage == "sensor_chain":
        return {"spn": c.strain_per_Nm, "sensor": _file_hash(c.sensor_file)}
    if stage == "calibration_session":
        return {"session": c.session}
    if stage == "simulation":        # noise-free: the sensors' noise model is not an input
        return {"sim": _canon(_quiet(scene.sim))}
    if stage == "sensor_log":
        return {"sensors": _canon(scene.sim.sensors), "base": scene.sim.base}
    if stage == "static_holds":
        return {"static": _canon(scene.static)}
    if stage == "paper_scores":
        return {"name": scene.name, "est": _canon(scene.estimator),
                "scene": _canon(scene.sim.pokes) if scene.sim is not None else _canon(scene.static)}
    if stage == "error_map":
        return {"prediction": _canon(scene.prediction), "robot": _canon(scene.robot),
                "cal": _file_hash(c.calibration_file)}
    if stage == "raw_counts":
        return {"gain": c.true_gain_factor, "seed": seed, "log": _file_hash(c.log_file),
                "cols": c.counts_columns, "unit": c.reading_unit,
                "ft": _canon(getattr(scene.sim, "sensors", None))}
    if stage == "calibrated_torques":
        return {"cal": _file_hash(c.calibration_file)}
    if stage in ("estimates", "localization_error", "predicted_error"):
        return {"est": _canon(scene.estimator), "poke": _canon(scene.sim.pokes if scene.sim else None),
                "robot": _canon(scene.robot)}        # the file the estimator reads
    return {}


def _canon(x):
    """A scene value as exact, JSON-able data for a cache key: dataclasses field by field, arrays
    by dtype, shape and a hash of their bytes, floats by ``repr`` (round-trip exact). ``repr`` of a
    numpy array keeps 8 digits and elides long arrays, so two different inputs could share a key."""
    import dataclasses

    if dataclasses.is_dataclass(x) and not isinstance(x, type):
        return {"type": type(x).__name__,
                **{f.name: _canon(getattr(x, f.name)) for f in dataclasses.fields(x)}}
    if isinstance(x, np.ndarray):
        a = np.ascontiguousarray(x)
        return {"dtype": a.dtype.str, "shape": list(a.shape),
                "sha256": hashlib.sha256(a.tobytes()).hexdigest()}
    if isinstance(x, dict):
        return {str(k): _canon(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_canon(v) for v in x]
    if isinstance(x, np.generic):
        return _canon(x.item())
    if isinstance(x, float):
        return repr(x)
    if x is None or isinstance(x, (str, int, bool)):
        return x
    return repr(x)


def _file_hash(p):
    """SHA-256 of a file's bytes (None: no file; an unreadable file keys as such and its reader
    reports it in one line when the stage runs)."""
    if not p:
        return None
    try:
        return hashlib.sha256(Path(p).read_bytes()).hexdigest()
    except OSError as exc:
        return f"unreadable: {p}: {type(exc).__name__}"


def _design_hash(p):
    """Hash of a flexure design file and of the files it names (``[geometry] file``, the STL or
    STEP part, and ``[bridge] sensor``, paths relative to the design): editing the part re-runs
    the FEM as editing the design does. The design is parsed here only for those two names;
    ``load_design`` validates it when the stage runs."""
    import tomllib

    key = {"design": _file_hash(p)}
    try:
        raw = tomllib.loads(Path(p).read_text())
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError):
        return key                                 # the stage's own reader names the problem
    for table, field in (("geometry", "file"), ("bridge", "sensor")):
        name = raw.get(table, {}).get(field) if isinstance(raw.get(table), dict) else None
        if isinstance(name, str):
            key[f"{table}.{field}"] = _file_hash(Path(p).parent / name)
    return key


# ---------------------------------------------------------------- the stage functions
def run_flexure_fem(scene, inp):
    """The design's figures as ``torquebench flexure`` gives them: the answer on the finest of three
    mesh levels, each figure with its discretisation error estimate (flexure.convergence)."""
    from flexure.convergence import design_figures   # the ONE call into the flexure package

    fx = design_figures(scene.chain.flexure_design)
    if fx.get("nan_reason"):
        raise InputError(f"{scene.path}: flexure.design: no trustworthy gauge strain ({fx['nan_reason']})")
    return fx


def run_sensor_chain(scene, inp):
    """The ONE sensor model: SensorChain(config of [sensor].file or the paper's, strain per N·m)."""
    from bridge.chain import PAPER_STRAIN_PER_NM, SensorChain
    from bridge.config import SensorConfig, load_sensor_config

    c = scene.chain
    config, spn = (load_sensor_config(c.sensor_file) if c.sensor_file else (SensorConfig(), None))
    if inp.get("flexure"):
        spn = inp["flexure"]["gauge_strain_per_Nm"]
    elif c.strain_per_Nm is not None:
        spn = c.strain_per_Nm
    return SensorChain(config, spn or PAPER_STRAIN_PER_NM)


def run_calibration_session(scene, inp):
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


def run_calibration_fit(scene, inp):
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


def adc_bits(scene) -> int:
    """The converter's width: the scene's [sensor] file's [adc] bits, else the default sensor's
    (bridge.config.SensorConfig: the one place the width is written)."""
    from bridge.config import SensorConfig, load_sensor_config

    c = scene.chain
    return (load_sensor_config(c.sensor_file)[0] if c.sensor_file else SensorConfig()).bits


def load_calibration(scene):
    import calibration

    return calibration.load(scene.chain.calibration_file)


def _quiet(cfg):
    """The scene's SimConfig with noise-free sensors at its sample rate (the integration reads
    only the rate; every sensor model is applied to the sampled truth afterwards)."""
    from dataclasses import replace

    from estimator.sim.config import Sensors

    quiet = Sensors(sample_rate_Hz=cfg.sensors.sample_rate_Hz, torque_model="gaussian",
                    torque_noise_Nm=0.0, ft_noise=[0.0, 0.0, 0.0], seed=0)
    return replace(cfg, sensors=quiet)


def run_simulation(scene, inp):
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

    from bridge.errors import ADCSaturationWarning
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


def run_calibrated_torques(scene, inp):
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


def _torque_from_counts(scene) -> bool:
    """Whether the estimates' torques are the simulated ADC codes of the sensor chain (a simulated
    scene's raw_counts, whatever [sensors].torque_model says), read back through the calibration."""
    return scene.sim is not None


def scene_noise_model(scene, chain=None, calibration=None, readings: str = "counts"):
    """The estimator's NoiseModel (estimator.noise) for the readings the scene's estimates see,
    with ``source`` naming where every σ came from; None when the scene states no sensors (a
    recorded log without counts columns: the estimator's own default then applies and says so).

    σ_τ per sample: torques read from ADC counts (every simulated scene's raw_counts, whatever
    [sensors].torque_model says) carry the chain's white noise
    σ_c = σ_τ,true · counts_per_Nm,true (true chain = the chain at true_gain_factor × strain),
    read back through the reader's slope: σ_τ = σ_c / (counts per N·m of the calibration, or of
    the nominal chain without one). The calibration's slope uncertainty is NOT white noise: it
    scales every sample of a run by the same factor (a bias of the torque, not a per-sample
    scatter), so it does not enter the detector's covariance (it enters predicted_error).
    readings="log": the log `simulate` writes (sensor_log): σ_τ = the chain's noise_std_Nm for
    torque_model "bridge" (estimator.sim.sensors.measure reads through ``chain``), else
    sensors.torque_noise_Nm.
    FT σ, joint-rate σ and encoder counts: the scene's [sensors] (what raw_counts draws).
    Raises InputError when a σ is zero (a zero-noise channel cannot be whitened)."""
    from dataclasses import replace

    from estimator.noise import NoiseModel

    sim = scene.sim
    if sim is None:                       # a recorded log states no sensor noise
        return None
    parts = []
    if readings == "log":
        if sim.sensors.torque_model == "bridge":
            chain = chain if chain is not None else run_sensor_chain(scene, {})
            sigma_tau = chain.noise_std_Nm
            parts.append(f"τ σ {sigma_tau:.3g} N·m = the bridge chain's noise_std_Nm")
        else:
            sigma_tau = sim.sensors.torque_noise_Nm
            parts.append("τ σ from sensors.torque_noise_Nm")
    elif chain is not None:
        true = replace(chain, strain_per_Nm=chain.strain_per_Nm * scene.chain.true_gain_factor)
        sigma_counts = true.noise_std_Nm * abs(true.counts_per_Nm)
        if calibration is not None:
            read = np.asarray(calibration.torque(np.array([0.0, 1.0])), float)
            per_count, by = abs(read[1] - read[0]), "the fitted calibration"
        else:
            per_count, by = 1.0 / abs(chain.counts_per_Nm), "the nominal chain"
        sigma_tau = sigma_counts * per_count
        parts.append(f"τ σ {sigma_tau:.3g} N·m = sensor chain noise {sigma_counts:.3g} counts "
                     f"(gain factor {scene.chain.true_gain_factor:g}) read through {by}")
    else:
        sigma_tau = sim.sensors.torque_noise_Nm
        parts.append("τ σ from sensors.torque_noise_Nm")
    sensors = sim.sensors
    parts.append("FT σ from sensors.ft_noise")
    if sensors.velocity_noise_rad_per_s:
        parts.append("q̇ σ from sensors.velocity_noise_rad_per_s")
    if sensors.encoder_counts:
        parts.append("encoder quantization from sensors.encoder_counts")
    sigmas = [sigma_tau, *np.asarray(sensors.ft_noise, float)]
    if not all(np.isfinite(v) and v > 0 for v in sigmas):
        raise InputError(f"{scene.path}: sensors: a zero σ (τ σ {sigma_tau:g} N·m, ft_noise "
                         f"{np.asarray(sensors.ft_noise).tolist()}) cannot whiten the residual "
                         "for the chi-square detector; give every σ > 0 or set [estimator] threshold")
    return NoiseModel(torque_sigma_Nm=[sigma_tau], ft_sigma=sensors.ft_noise,
                      velocity_sigma_rad_per_s=sensors.velocity_noise_rad_per_s,
                      encoder_counts=sensors.encoder_counts,
                      source=f"scene {scene.name}: " + "; ".join(parts))


def run_estimates(scene, inp):
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


def run_localization_error(scene, inp):
    est, tr = inp["estimates"], inp["truth"]
    truth = _truth_rows(tr["truth"], est["kept"])
    out = {"flagged_samples": est["flagged_samples"]}
    for m in METHODS:
        out[m] = collision_phase_errors(est[m], truth, scene.sim.pokes, scene.estimator.gain_per_s)
    return out


def run_predicted_error(scene, inp, draws=2000):
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


def run_sensor_log(scene, inp):
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


def run_static_holds(scene, inp):
    """Static equilibria (estimator.sim.static.static_hold_log): every point held for hold_s
    after a 0.3 s no-load tare. Returns {log, truth, stats}."""
    from estimator.sim.static import static_hold_log

    st = scene.static
    start = time.perf_counter()
    pts = st.points
    log, truth, _ = static_hold_log(st.robot, np.array([p.q_rad for p in pts]),
                                    np.array([p.link for p in pts]), np.array([p.alpha for p in pts]),
                                    np.array([p.force_N for p in pts]), st.sensors, st.hold_s,
                                    tare_s=0.3)
    return {"log": log, "truth": truth,
            "stats": {"integrator": "static", "run_time_s": time.perf_counter() - start,
                      "points": len(pts)}}


def run_paper_scores(scene, inp):
    """The paper reproduction's scores (torquebench.reports.reproduction): a dynamic scene's
    simulated log through both methods, or a static scene's holds."""
    from types import SimpleNamespace

    from torquebench.reports import reproduction as rr

    if scene.sim is None:
        return rr.evaluate_static(scene)
    lg = inp["log"]
    res = SimpleNamespace(t=lg["log"].t, truth=lg["truth"], log=lg["log"], stats=lg["stats"])
    return rr.evaluate_dynamic(scene, res, chain=inp.get("chain"))


def calibration_noise(cal, chain=None) -> tuple[float, str, list]:
    """σ_τ of one torque reading from a calibration: its reading noise through its slope,
    σ_τ = σ_reading / |slope| · 10⁻³ g L (N·m), and how it compares with the sensor chain's noise
    budget and sensitivity (a warning when they differ by more than 2×: another sensor, another
    unit, or readings averaged over several ADC samples)."""
    i = list(cal.coef_names).index("slope")
    slope = abs(float(cal.coef_mean[i]))
    per_Nm = slope / cal._torque_per_g()                 # reading units per N·m
    sigma = float(cal.sigma) / per_Nm
    source = (f"the calibration's reading noise ({cal.sigma:.3g} {cal.reading_unit or 'reading units'} "
              f"through its slope, {cal.source})")
    warnings = []
    if chain is not None:
        ratio = sigma / chain.noise_std_Nm
        if not 0.5 <= ratio <= 2.0:
            warnings.append(f"the calibration's σ_τ {sigma:.3g} N·m is {ratio:.2g}× the sensor chain's "
                            f"{chain.noise_std_Nm:.3g} N·m: is the chain (sensor file, strain per N·m) "
                            f"this sensor's, or were its readings averages of several samples?")
        if cal.reading_unit == "counts":
            s_ratio = per_Nm / abs(chain.counts_per_Nm)
            if not 0.5 <= s_ratio <= 2.0:
                warnings.append(f"the calibration's sensitivity {per_Nm:.4g} counts/N·m is {s_ratio:.2g}× "
                                f"the sensor chain's {abs(chain.counts_per_Nm):.4g}")
    return sigma, source, warnings


def run_error_map(scene, inp):
    """Localization error over the posture grid q ∈ [0, π]^n (estimator.uncertainty): Monte Carlo
    and first order, per method, with σ_τ from the sensor chain (or given), the calibration's
    relative slope std as a gain error (or given), the FT noise and the robot's parameter
    uncertainty (given, else the robot file's identification or declared uncertainty)."""
    from estimator.uncertainty import SensorNoise, first_order, monte_carlo

    pr, robot = scene.prediction, scene.robot
    cal, chain = inp.get("calibration"), inp.get("chain")
    sigma_tau, tau_source, warnings = pr.torque_noise_Nm, "given", []
    if sigma_tau is None and cal is not None and cal.lever_arm_m is not None:
        sigma_tau, tau_source, warnings = calibration_noise(cal, chain)
    elif sigma_tau is None:
        sigma_tau, tau_source = chain.noise_std_Nm, "the sensor chain's noise budget"
    gain_error = pr.gain_error
    if gain_error is None and cal is not None:
        i = list(cal.coef_names).index("slope")
        gain_error = math.sqrt(cal.coef_cov[i, i]) / abs(cal.coef_mean[i])
    noise = SensorNoise(torque_std_Nm=sigma_tau, wrench_std=list(pr.ft_noise),
                        torque_gain_rel_std=gain_error or 0.0, sample_rate_Hz=pr.sample_rate_Hz,
                        gain_per_s=pr.gain_per_s)
    force = pr.magnitude_N * np.array([math.cos(pr.direction_rad), math.sin(pr.direction_rad)])
    from estimator.model import ModelUncertainty
    from estimator.model_error import resolve

    mu = pr.model_uncertainty
    cov, cov_source = resolve(robot, None if mu is None else
                              (ModelUncertainty.uniform(mu) if mu > 0 else False))
    axes = [np.linspace(0.0, math.pi, pr.grid)] * robot.n_links
    postures = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, robot.n_links)
    out = {"noise": noise, "axes": axes, "postures": len(postures), "methods": {}, "maps": {},
           "model_uncertainty_source": cov_source, "torque_noise_source": tau_source,
           "warnings": warnings}
    for method in METHODS:
        mc = monte_carlo(robot, postures, pr.link, pr.alpha, force, noise, draws=pr.draws,
                         rng=pr.seed, method=method, parameter_cov=cov)
        fo = first_order(robot, postures, pr.link, pr.alpha, force, noise, method=method,
                         parameter_cov=cov)
        usable = mc.flagged_fraction < 0.05
        pos = mc.position_rms_m[usable]
        ratio = mc.position_rms_m[usable] / fo.position_rms_m[usable]
        worst = int(np.flatnonzero(usable)[np.argmax(mc.position_p95_m[usable])]) if pos.size else None
        out["methods"][method] = {
            "position_rms_median_m": float(np.median(pos)) if pos.size else None,
            "position_rms_median_m_error_estimate":
                float(np.median(mc.position_rms_se_m[usable])) if pos.size else None,
            "position_rms_median_m_error_method":
                f"Monte Carlo standard error (1 sigma, delta method), median over postures, {pr.draws} draws",
            "position_rms_max_m": float(np.max(pos)) if pos.size else None,
            "position_p95_max_m": float(np.max(mc.position_p95_m[usable])) if pos.size else None,
            "position_p95_max_m_error_estimate":
                float(mc.position_p95_se_m[worst]) if pos.size else None,
            "position_p95_max_m_error_method":
                f"Monte Carlo standard error (1 sigma) of the 95th percentile at the worst posture, "
                f"from the binomial spread of order statistics, {pr.draws} draws",
            "force_rms_median_N": float(np.median(mc.force_rms_N[usable])) if pos.size else None,
            "flagged_postures": int((~usable).sum()),
            "monte_carlo_over_first_order_median": float(np.median(ratio)) if pos.size else None,
        }
        out["maps"][method] = np.where(usable, mc.position_rms_m, np.nan)
    out["bounds"] = bound_maps(robot, postures, pr, sigma_tau)
    return out


def bound_maps(robot, postures, pr, sigma_tau) -> dict:
    """The Cramér–Rao bound and our estimator's predicted error over the postures × force
    directions (estimator.bound_maps), the scene's direction first; {} with a reason when a zero
    σ leaves nothing to whiten."""
    from estimator.bound_maps import localization_maps
    from estimator.noise import NoiseModel

    if not (sigma_tau > 0 and all(v > 0 for v in pr.ft_noise)):
        return {"reason": "a zero sensor σ: the residual cannot be whitened, no bound"}
    dirs = pr.direction_rad + 2 * math.pi * np.arange(pr.directions) / pr.directions
    dirs = (dirs + math.pi) % (2 * math.pi) - math.pi
    noise = NoiseModel(torque_sigma_Nm=[sigma_tau], ft_sigma=list(pr.ft_noise))
    m = localization_maps(robot, postures, pr.link, pr.alpha, pr.magnitude_N, dirs, noise,
                          pr.gain_per_s, 1.0 / pr.sample_rate_Hz, pr.hold_s,
                          draws=min(pr.draws, 200), seed=pr.seed)
    m["directions_rad"] = dirs
    return m


def run_report(scene, inp):
    """The chosen views of the scene's own results (torquebench.scene_views: markdown + pictures
    drawn from ``inp`` only) into the scene's output directory, and ``<scene>.md``: the summary of
    what this scene computed followed by the views' sections."""
    from userio.files import write_text_atomic

    out_dir = report_dir(scene)
    out_dir.mkdir(parents=True, exist_ok=True)
    have = {k for k, v in inp.items() if v is not None}
    areas, _ = report_areas(scene, have)
    written, sections = {}, []
    for area in areas:
        lines, paths = VIEWS[area].draw(scene, inp, out_dir)
        sections += lines
        written[area] = [str(p) for p in paths]
    summary = out_dir / summary_name(scene)
    write_text_atomic(summary, scene_summary(scene, inp, sections))
    return {"dir": str(out_dir), "areas": areas, "written": written, "summary": str(summary)}


def scene_summary(scene, arts, sections=()) -> str:
    """Markdown: the figures this scene computed (the formatters `run` prints with,
    torquebench.formatting), then ``sections`` (the report views drawn)."""
    L = [f"# Scene {scene.name}", "", scene.description or "", "",
         f"Generated by `torquebench run {scene.path}`.", ""]
    ch = arts.get("chain")
    if ch is not None:
        L += ["## Sensor", "", f"- strain per N·m: {ch.strain_per_Nm:.4g}",
              f"- torque noise σ_τ: {ch.noise_std_Nm:.4g} N·m per sample", ""]
    fx = arts.get("flexure")
    if fx:
        L += ["## Flexure (FEM)", "", f"- {fmt.flexure_text(fx)}", ""]
    cal = arts.get("calibration")
    if cal is not None:
        L += ["## Calibration", "", f"- {fmt.calibration_text(cal)}", ""]
    me, pr = arts.get("localization_error"), arts.get("predicted_error")
    if me or pr:
        L += ["## Localization error (collision phase)", "",
              *fmt.markdown_table(["method", "measured RMS", "predicted RMS (MC, 1σ)", "predicted p95"],
                                  [[m, *fmt.error_cells(me, pr, m)] for m in METHODS]), ""]
    return "\n".join(L + list(sections))


RUNNERS = {"flexure_fem": run_flexure_fem, "sensor_chain": run_sensor_chain,
           "calibration_session": run_calibration_session, "calibration_fit": run_calibration_fit,
           "simulation": run_simulation, "raw_counts": run_raw_counts,
           "calibrated_torques": run_calibrated_torques, "estimates": run_estimates,
           "localization_error": run_localization_error, "predicted_error": run_predicted_error,
           "sensor_log": run_sensor_log, "static_holds": run_static_holds,
           "paper_scores": run_paper_scores, "error_map": run_error_map, "report": run_report}


# ---------------------------------------------------------------- the graph
@dataclass
class Step:
    stage: Stage
    action: str           # "run" | "skip" | "cached"
    reason: str
    key: str = ""


def _feasible(scene, art: str) -> str | None:
    """Why ``art`` cannot be produced by this scene, or None."""
    c = scene.chain
    if art == "flexure" and c.flexure_design is None:
        return "no [flexure].design"
    if art == "session" and c.session is None:
        return "no simulated session in [calibration]"
    if art == "calibration" and c.session is None and c.calibration_file is None:
        return "no [calibration] (file or simulated session)"
    if art in ("truth", "localization_error") and scene.sim is None:
        return "no simulation (a recorded log has no truth)" if c.log_file else "not a dynamic scene"
    if art == "predicted_error" and scene.sim is None:
        return "the prediction needs the scene's contact (a simulated poke)"
    if art == "predicted_error" and not scene.sim.pokes:
        return "no poke in the scene"
    if art == "localization_error" and not scene.sim.pokes:
        return "no poke in the scene"
    if art == "torques" and c.log_file is None and scene.sim is None:
        return "no source"
    if art == "log" and scene.sim is None:
        return "not a dynamic simulation" + (" (a recorded log is read as it is)" if c.log_file else "")
    if art == "static_log" and scene.static is None:
        return "not a static scene (static_loading or posture_sweep)"
    if art == "paper_scores" and scene.sim is None and scene.static is None:
        return "no simulated scene to score"
    if art == "error_map" and scene.prediction is None:
        return "no posture-grid prediction settings (`propagate` builds them from its options)"
    return None


def report_dir(scene) -> Path:
    """Where the scene's reports go: [outputs].dir, else ./out/<scene name as a safe file stem>
    (never the shipped reports/ unless [outputs].regenerate_shipped)."""
    from userio.outputs import safe_stem

    d = scene.chain.report_dir
    return Path(d) if d is not None else Path("out") / safe_stem(scene.name, "scene")


def summary_name(scene) -> str:
    """The scene summary's file name: ``<scene name as a safe file stem>.md`` (a name like
    "../x" or "notes" never leaves the report directory nor takes another file's name there)."""
    from userio.outputs import safe_stem

    return f"{safe_stem(scene.name, 'scene')}.md"


def report_areas(scene, have: set) -> tuple[list[str], list[tuple[str, str]]]:
    """(views to draw, [(area, why not)]): a view is drawn when the scene computes what it shows
    (``have``: the artifacts the other outputs need); a view listed in [outputs].reports whose
    input the scene cannot produce is an error, and so is an area that is not about one scene (a
    shipped report of torquebench/reports with no view here)."""
    from torquebench.scenes import report_areas_available

    chosen = scene.chain.report_areas
    run, skipped = [], []
    for area in sorted(set(report_areas_available()) | set(VIEWS)):
        art = REPORT_INPUTS.get(area)
        if chosen is not None and area not in chosen:
            skipped.append((area, "not in outputs.reports"))
            continue
        if art is None:
            if chosen is not None:
                raise InputError(f"{scene.path}: outputs.reports: {area!r} is not about one scene; "
                                 f"run `torquebench report --only {area}`")
            skipped.append((area, "not about one scene"))
            continue
        if chosen is not None:
            why = None if art == "calibration" and scene.chain.calibration_file else _feasible(scene, art)
            if why:
                raise InputError(f"{scene.path}: outputs.reports: {area!r} needs {art}, which this "
                                 f"scene cannot produce ({why})")
            run.append(area)
        elif art in have:
            run.append(area)
        else:
            skipped.append((area, f"the scene computes no {art}"))
    return run, skipped


def _uses(scene, stage: str, art: str) -> bool:
    """Whether ``stage`` reads its declared input ``art`` for this scene (some inputs depend on
    the scene: the bridge chain only for a bridge torque model, a calibration only when no gain
    error is given, ...)."""
    if stage == "sensor_log" and art == "chain":
        return scene.sim.sensors.torque_model == "bridge"
    if stage == "error_map" and art == "chain":
        return scene.prediction.torque_noise_Nm is None
    if stage == "error_map" and art == "calibration":
        return scene.prediction.gain_error is None and scene.chain.calibration_file is not None
    if stage == "estimates" and art in ("chain", "calibration"):
        return _torque_from_counts(scene)        # σ_τ of the torques read from counts
    if stage == "paper_scores" and art == "log":
        return scene.sim is not None
    if stage == "paper_scores" and art == "chain":    # σ_τ of a bridge log for the detector
        return scene.sim is not None and scene.sim.sensors.torque_model == "bridge"
    if stage == "report":
        return False                     # its inputs are planned by report_areas
    return True


def plan(scene, outputs=None, cache=None, seed=None, force=False) -> list[Step]:
    """Steps in execution order, built backwards from ``outputs``."""
    default = DEFAULT_OUTPUTS if scene.sim is not None else ("estimates",) if scene.chain.log_file \
        else ("error_map",) if scene.prediction is not None \
        else ("sensitivity",)          # a static scene: the sensor model only (run by `reproduce`)
    wants = [ALIASES.get(o, o) for o in (outputs or scene.chain.outputs or default)]
    for w in wants:
        if w not in BY_GIVES:
            raise InputError(f"{scene.path}: outputs: unknown output {w!r}")
        why = _feasible(scene, w)
        if why:
            raise InputError(f"{scene.path}: outputs: nothing in the scene can produce {w!r} ({why})")
    needed: dict[str, str] = {}

    def visit(art, reason):
        if art in needed:
            return
        if art == "calibration" and scene.chain.calibration_file is not None:
            needed[art] = "given"
            return
        if art == "readings" and scene.chain.log_file is None and scene.sim is None:
            return
        needed[art] = reason
        st = BY_GIVES[art]
        for n in st.needs:
            opt = n.endswith("?")
            n = n.rstrip("?")
            if not _uses(scene, st.name, n):
                continue
            if n == "truth" and scene.chain.log_file is not None and art == "readings":
                continue
            if opt and (given(scene, n) or _feasible(scene, n)):
                continue
            visit(n, f"needed by {st.name}")

    for w in wants:
        if w != "report":
            visit(w, "requested output")
    if "report" in wants:
        areas, _ = report_areas(scene, set(needed))
        needed["report"] = "requested output"
        for art in sorted({REPORT_INPUTS[a] for a in areas}):
            visit(art, "needed by report")
    seed = scene_seed(scene) if seed is None else seed
    steps, keys = [], {}
    for st in STAGES:
        if st.gives not in needed:
            g = given(scene, st.gives)
            steps.append(Step(st, "skip", g or "not needed for the requested outputs"))
            continue
        if needed[st.gives] == "given":
            steps.append(Step(st, "skip", given(scene, st.gives)))
            continue
        if st.gives == "readings" and scene.chain.log_file is not None:
            pass
        if st.name == "report":          # writes files: always runs, never cached
            areas, skipped = report_areas(scene, set(needed) - {"report"})
            why = "; ".join(f"{a} ({r})" for a, r in skipped)
            steps.append(Step(st, "run", f"{needed[st.gives]}; views: {', '.join(areas) or 'none'}"
                              f" + the scene summary, into {report_dir(scene)}"
                              + (f"; not drawn: {why}" if why else "")))
            continue
        up = [keys.get(n.rstrip("?"), "") if _uses(scene, st.name, n.rstrip("?")) else ""
              for n in st.needs]
        key = _key(st.name, _params(scene, st.name, seed), up)
        keys[st.gives] = key
        if cache is not None and not force and cache.has(key):
            steps.append(Step(st, "cached", f"{needed[st.gives]}; result in the cache", key))
        else:
            steps.append(Step(st, "run", needed[st.gives], key))
    return steps


def _key(stage, params, upstream) -> str:
    blob = json.dumps({"stage": stage, "params": params, "up": upstream, "code": CODE_VERSION,
                       "packages": stage_code(stage)}, sort_keys=True, default=str)
    return hashlib.sha256(blob.encode()).hexdigest()[:32]


def scene_seed(scene) -> int:
    s = scene.sim.sensors.seed if scene.sim is not None else 0
    return int(s)


def execute(scene, outputs=None, cache=None, seed=None, force=False, counter=None) -> tuple[dict, list]:
    """Run the plan; returns (artifacts, [(stage, action, seconds)])."""
    seed = scene_seed(scene) if seed is None else seed
    steps = plan(scene, outputs, cache, seed, force)
    arts, timing = {}, []
    if any(s.stage.gives == "calibration" and s.action == "skip" and scene.chain.calibration_file
           for s in steps) and _wanted_cal(scene, steps):
        arts["calibration"] = load_calibration(scene)
    for s in steps:
        if s.action == "skip":
            continue
        t0 = time.perf_counter()
        if s.action == "cached":
            value = cache.get(s.key)
            if value is None:                    # corrupt entry: reported by the cache, recompute
                s.action = "run"
        if s.action == "run":
            fn = RUNNERS[s.stage.name]
            inp = {n.rstrip("?"): arts.get(n.rstrip("?")) for n in s.stage.needs}
            value = fn(scene, inp, seed) if s.stage.name == "raw_counts" else fn(scene, inp)
            if counter is not None:
                counter[s.stage.name] = counter.get(s.stage.name, 0) + 1
            if cache is not None and s.key:
                cache.put(s.key, value)
        arts[s.stage.gives] = value
        timing.append((s.stage.name, s.action, time.perf_counter() - t0))
    return arts, timing


def _wanted_cal(scene, steps):
    return any(s.action != "skip" and "calibration" in [n.rstrip("?") for n in s.stage.needs]
               and _uses(scene, s.stage.name, "calibration") for s in steps)
