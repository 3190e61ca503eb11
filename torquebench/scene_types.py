"""What a scene is once read: its dataclasses (the scene, its estimator settings, its static
holds, what it gives for the sensor chain, a posture-grid prediction). Read by
torquebench.scenes.load_scene."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from estimator.robot import Robot
from estimator.sim.config import Sensors, SimConfig
from estimator.limits import ALPHA_RANGE, FORCE_RANGE, GAIN_RANGE, SAMPLE_RATE_RANGE, THRESHOLD_RANGE
from estimator.noise import FT_SIGMA_RANGE, TORQUE_SIGMA_RANGE
from userio.fields import Range, ranged

G_M_PER_S2 = 9.81
KINDS = ("dynamic", "static_loading", "posture_sweep")


@dataclass(frozen=True)
class EstimatorSettings:
    """[estimator]: threshold None → ``dynamic`` detects with the chi-square test at
    ``false_alarm_rate`` (value, unit 'sample' | 's' | 'h') on the residual whitened by the scene's
    sensor noise (pipeline.scene_noise_model); ``paper`` keeps ε = 0.06. A threshold given → the
    paper's rule ‖r‖ > threshold for both methods. ``quiet_window_s`` (t0, t1): the residual's
    covariance is estimated robustly from that contact-free stretch of the log instead (the way to
    state the noise of a recorded log, whose sensors the scene does not describe)."""

    method: str = "dynamic"
    gain_per_s: float = ranged(100.0, GAIN_RANGE)
    threshold: float | None = ranged(None, THRESHOLD_RANGE)
    false_alarm_rate: tuple = (1.0, "h")
    quiet_window_s: tuple | None = None


@dataclass(frozen=True)
class StaticPoint:
    q_rad: np.ndarray
    link: int
    alpha: float
    force_N: np.ndarray
    label: str = ""


@dataclass(frozen=True)
class StaticScene:
    """Static holds: every point is held for ``hold_s``; the estimate is read over the last
    ``window_s`` of each hold (the observer has settled: window starts ≥ 5/K after the change)."""

    name: str
    kind: str
    robot: Robot
    points: tuple[StaticPoint, ...]
    sensors: Sensors
    hold_s: float = 0.15
    window_s: float = 0.08
    grid_shape: tuple = ()


@dataclass(frozen=True)
class ChainSpec:
    """What the scene gives for the sensor chain (torquebench.pipeline reads it).

    ``[flexure]``: ``design`` (a flexure TOML, run through the FEM) or ``strain_per_Nm``;
    ``[sensor]``: ``file`` (bridge/amplifier/ADC TOML) and ``true_gain_factor`` (the real sensor's
    gain over its model: 1.05 = 5 % more sensitive than calibrated, for validation);
    ``[calibration]``: ``file`` (a stored calibration JSON) or a simulated loading session
    (``masses_g``, ``lever_arm_m``, ``repeats``, ``n_avg``, ``seed``) fitted with emcee;
    ``[source]``: ``log`` (a recorded CSV, optionally with raw sensor ``counts_columns`` holding
    ``reading_unit`` "counts" (ADC codes, the default) or "mV", which a stored calibration must
    read) or, when absent, the simulation of the scene's top-level keys; ``[outputs] want = [...]``.
    """

    flexure_design: Path | None = None
    strain_per_Nm: float | None = None
    sensor_file: Path | None = None
    true_gain_factor: float = 1.0
    calibration_file: Path | None = None
    session: dict | None = None              # masses_g, lever_arm_m, repeats, n_avg, seed
    log_file: Path | None = None
    counts_columns: tuple = ()
    outputs: tuple = ()
    reading_unit: str = "counts"             # what counts_columns hold: raw ADC "counts" or "mV"
    report_areas: tuple | None = None        # [outputs] reports (None: every area the scene feeds)
    report_dir: Path | None = None           # [outputs] dir (None: ./out/<scene name>)
    regenerate_shipped: bool = False         # [outputs] regenerate_shipped: may write reports/


@dataclass(frozen=True)
class PredictionSpec:
    """A posture-grid localization-error prediction (what `propagate` asks): contact (link, α),
    force (magnitude, direction from +x), ``grid`` postures per joint over [0, π], Monte Carlo
    ``draws`` and ``seed``, sample rate, observer gain, FT noise σ (Fx, Fz, My); an optional
    given joint-torque σ (else the sensor chain's) and gain error (else the calibration's), the
    robot's model uncertainty; the bound maps' hold time and number of force directions."""

    link: int
    alpha: float = ranged(0.8, ALPHA_RANGE)
    magnitude_N: float = ranged(7.0, FORCE_RANGE)
    direction_rad: float = 0.0
    grid: int = ranged(10, Range(1, 1000, "postures per joint"))
    draws: int = ranged(500, Range(2, 1e7, "draws per posture"))
    seed: int = 0
    sample_rate_Hz: float = ranged(1000.0, SAMPLE_RATE_RANGE)
    gain_per_s: float = ranged(100.0, GAIN_RANGE)
    ft_noise: tuple = ranged((0.1, 0.1, 0.01), FT_SIGMA_RANGE)
    torque_noise_Nm: float | None = ranged(None, TORQUE_SIGMA_RANGE)
    gain_error: float | None = ranged(None, Range(0.0, 1.0, "(relative)"))
    model_uncertainty: float | None = ranged(None, Range(0.0, 1.0, "(relative)"))   # 1σ of the
    # inertial data (0: none; None: the robot file's identification or [model_uncertainty])
    hold_s: float = 0.5                  # the episode bound's hold time (estimator.bound_maps)
    directions: int = 24                 # force directions of the bound maps


@dataclass(frozen=True)
class Scene:
    name: str
    kind: str
    path: Path
    description: str
    sim: SimConfig | None
    static: StaticScene | None
    estimator: EstimatorSettings = field(default_factory=EstimatorSettings)
    chain: ChainSpec = field(default_factory=ChainSpec)
    robot: Robot | None = None
    prediction: PredictionSpec | None = None
    max_run_time_s: float = 600.0          # a run limit, not an input: not part of any cache key
    robot_file: Path | None = None         # the robot TOML the scene named (an input of the run)


