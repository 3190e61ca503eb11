"""A planar scene (``scenes/paper_floating_link1.toml``): what to simulate or read, and what to
compute from it. Three kinds: ``dynamic`` (one time simulation, or a recorded log), ``static_loading``
(masses hung on a held leg), ``posture_sweep`` (a posture grid × contact points × one force).

Checks that need the robot (how many joints a vector holds, link numbers) or the file system (the
files a scene names, the report directory) are made by the reader, torquebench.scenes, in the same
one-line style.
"""

from __future__ import annotations

from typing import Annotated, Literal, Optional, Union

import numpy as np
from pydantic import AfterValidator, model_validator
from pydantic_core import PydanticCustomError

from calibration.session import LEVER_ARM_RANGE_M, MASS_RANGE_G
from estimator.limits import ALPHA_RANGE, FORCE_RANGE, GAIN_RANGE, SAMPLE_RATE_RANGE, THRESHOLD_RANGE
from estimator.sim import config as sim
from userio.ranges import field_range
from userio.schema.base import Field, Model, Range, fail, integer, num, one_of, vector

G_M_PER_S2 = 9.81
KINDS = ("dynamic", "static_loading", "posture_sweep")
#: the vocabulary of ``[outputs] want``: the names the stage declarations offer a scene
#: (torquebench.stages.registry.scene_outputs), passed in by the reader (``OneOf``)
WANTABLE = "scene_outputs"
SESSION_KEYS = ("masses_g", "lever_arm_m", "repeats", "n_avg", "seed")
MAX_SESSION_SAMPLES = 2e7            # ADC codes a simulated calibration session draws (160 MB)
SIM_KEYS = ("controller", "poke", "ground", "integrator", "mount")


def _r(cls, name: str) -> Range:
    """The physical range declared on a simulation dataclass's field (estimator.sim.config)."""
    return field_range(cls, name)


class Harmonics:
    """One number per joint, or per joint a list of H harmonics (a Fourier excitation): finite,
    every value inside ``rng``."""

    def __init__(self, rng: Range | None = None, ge: float | None = None):
        self.rng, self.ge = rng, ge

    def __call__(self, v):
        num_ = lambda x: isinstance(x, (int, float)) and not isinstance(x, bool)   # noqa: E731
        rows = all(isinstance(r, list) and r and all(num_(x) for x in r) for r in v)
        if not v or not (all(num_(x) for x in v) or rows):
            raise PydanticCustomError("range", "expected one number per joint, or per joint a list "
                                      "of harmonics, got {v!r}", {"v": v})
        if rows and len({len(r) for r in v}) > 1:
            raise PydanticCustomError("range", "every joint needs the same number of harmonics", {})
        arr = np.asarray(v, float)
        if not np.all(np.isfinite(arr)):
            raise PydanticCustomError("range", "values must be finite, got {v!r}", {"v": v})
        for x in arr.ravel():
            if self.ge is not None and x < self.ge:
                raise PydanticCustomError("range", "values must be ≥ {ge:g}, got {x:g}",
                                          {"ge": self.ge, "x": float(x)})
            why = self.rng.problem(float(x)) if self.rng is not None else None
            if why:
                raise PydanticCustomError("range", "{why}", {"why": why})
        return v


def harmonics(rng=None, ge=None):
    return Annotated[list, AfterValidator(Harmonics(rng, ge))]


class RobotRef(Model):
    """``[robot]``: the robot file, and (dynamic scenes) the robot actually simulated."""

    file: str = Field("paper_leg.toml", description="the robot the estimator reads (beside the "
                      "scene or in robots/)")
    true_parameters: Optional[str] = Field(
        None, description="simulate this robot instead (same links, other inertial data)")
    perturbation: Optional[num(ge=0, le=0.5)] = Field(
        None, description="simulate the file's robot with masses, inertias and (× link length) "
        "centres of mass perturbed by this relative 1σ")
    perturbation_seed: Optional[integer(ge=0)] = Field(None, description="its seed (default 0)")

    @model_validator(mode="after")
    def _one_truth(self):
        if self.perturbation_seed is not None and self.perturbation is None:
            raise fail("perturbation_seed", "is the seed of a perturbation; set robot.perturbation")
        if self.true_parameters is not None and self.perturbation is not None:
            raise fail("perturbation", "give either true_parameters or a perturbation, not both")
        return self


class Controller(Model):
    """``[controller]``: joint PD to q0 + Σ A sin(2π f t + φ) (estimator.sim.config.Controller)."""

    q0_rad: vector(None, _r(sim.Controller, "q0_rad")) = Field(description="set point, one per joint")
    kp: num(_r(sim.Controller, "kp"), ge=0) = Field(500.0, description="stiffness, N·m/rad")
    kd: num(_r(sim.Controller, "kd"), ge=0) = Field(10.0, description="damping, N·m·s/rad")
    mode: Literal["continuous", "zoh"] = Field(
        "continuous", description="torque at every integrator stage, or held over 1/rate_Hz")
    rate_Hz: num(_r(sim.Controller, "rate_Hz"), gt=0) = Field(1000.0, description="servo rate (zoh)")
    amplitude_rad: Optional[harmonics(_r(sim.Controller, "amplitude_rad"))] = Field(
        None, description="sine amplitude per joint, or per joint a list of harmonics")
    frequency_Hz: Optional[harmonics(_r(sim.Controller, "frequency_Hz"), ge=0)] = Field(
        None, description="their frequencies (the amplitudes' shape); below the log's Nyquist")
    phase_rad: Optional[harmonics()] = Field(None, description="their phases (default 0)")
    gravity_compensation: bool = Field(False, description="add the joints' gravity torque")


class Poke(Model):
    """``[[poke]]``: a point force on (link, α) from t_on_s to t_off_s (one at a time)."""

    link: integer(ge=1) = Field(description="link number, 1..N")
    alpha: num(ALPHA_RANGE, ge=0, le=1) = Field(description="position along the link, 0..1")
    magnitude_N: Optional[num(FORCE_RANGE, ge=0)] = Field(None, description="force magnitude")
    direction_rad: Optional[num()] = Field(None, description="force direction from +x")
    mass_kg: Optional[num(gt=0)] = Field(None, description="or a hung mass (force m·g downwards)")
    t_on_s: num(sim.TIME_RANGE, ge=0) = Field(0.0, description="start")
    t_off_s: Optional[num(sim.TIME_RANGE, ge=0)] = Field(None, description="end (default: duration_s)")
    ramp_s: num(_r(sim.Poke, "ramp_s"), ge=0) = Field(0.0, description="linear ramp at each end")

    @model_validator(mode="after")
    def _force(self):
        if self.mass_kg is not None:
            if self.magnitude_N is not None or self.direction_rad is not None:
                raise fail("mass_kg", "give either mass_kg or magnitude_N + direction_rad")
            why = FORCE_RANGE.problem(self.mass_kg * G_M_PER_S2)
            if why:
                raise fail("mass_kg", f"mass_kg × g: {why}")
        else:
            for k in ("magnitude_N", "direction_rad"):
                if getattr(self, k) is None:
                    raise fail(k, "missing field (or give mass_kg)")
        return self


class Ground(Model):
    """``[ground]``: a flat floor under the foot (estimator.sim.config.Ground)."""

    height_m: num(_r(sim.Ground, "height_m")) = Field(0.0, description="floor height z")
    stiffness_N_per_m: num(_r(sim.Ground, "stiffness_N_per_m"), gt=0) = Field(2e4, description="normal stiffness")
    damping_Ns_per_m: num(_r(sim.Ground, "damping_Ns_per_m"), ge=0) = Field(200.0, description="normal damping")
    tangential_stiffness_N_per_m: num(_r(sim.Ground, "tangential_stiffness_N_per_m"), gt=0) = Field(
        2e4, description="bristle stiffness")
    friction_coefficient: Optional[num(_r(sim.Ground, "friction_coefficient"), ge=0)] = Field(
        None, description="μ (default: the robot's)")


class Sensors(Model):
    """``[sensors]``: how the truth is sampled (estimator.sim.config.Sensors)."""

    sample_rate_Hz: num(SAMPLE_RATE_RANGE, gt=0) = Field(1000.0, description="log sample rate")
    torque_model: Literal["gaussian", "bridge"] = Field(
        "gaussian", description="gaussian σ, or read through the bridge/ADC chain")
    torque_noise_Nm: Optional[num(_r(sim.Sensors, "torque_noise_Nm"), ge=0)] = Field(
        None, description="joint torque σ (gaussian; default 0.01)")
    ft_noise: vector(3, _r(sim.Sensors, "ft_noise"), ge=0) = Field(
        (0.1, 0.1, 0.01), description="FT σ [Fx N, Fz N, My N·m]")
    encoder_counts: integer(_r(sim.Sensors, "encoder_counts"), ge=0) = Field(
        0, description="encoder counts per revolution (0: no quantization)")
    velocity_noise_rad_per_s: num(_r(sim.Sensors, "velocity_noise_rad_per_s"), ge=0) = Field(
        0.0, description="joint-rate noise σ")
    seed: integer(ge=0) = Field(0, description="noise seed")

    @model_validator(mode="after")
    def _never_ignored(self):
        if self.torque_model == "bridge" and self.torque_noise_Nm is not None:
            raise fail("torque_noise_Nm", "is ignored with torque_model = \"bridge\" (the bridge "
                       "chain sets the noise); remove it or use torque_model = \"gaussian\"")
        return self


class Integrator(Model):
    """``[integrator]``: the ODE solver."""

    method: Literal[sim.INTEGRATORS] = Field("BDF", description="scipy solve_ivp method, or RK4 (fixed step)")
    rtol: num(ge=1e-13, le=1e-2) = Field(1e-6, description="relative tolerance (a 1 % cap)")
    atol: num(gt=0, le=1e-2) = Field(1e-8, description="absolute tolerance")
    fixed_step_s: num(_r(sim.SimConfig, "fixed_step_s"), gt=0) = Field(5e-5, description="RK4 step")


class Mount(Model):
    """``[mount]``: the base's spring-dampers, replacing the robot file's."""

    stiffness: vector(3, _r(sim.SimConfig, "mount_stiffness"), ge=0) = Field(
        description="[x N/m, z N/m, θ N·m/rad]")
    damping: vector(3, _r(sim.SimConfig, "mount_damping"), ge=0) = Field(
        description="[x N·s/m, z N·s/m, θ N·m·s/rad]")


class Estimator(Model):
    """``[estimator]``: the observer and the detector."""

    method: Literal["dynamic", "paper"] = Field(
        "dynamic", description="dynamic: chi-square test at false_alarm_rate on the whitened "
        "residual; paper: ‖r‖ > threshold (ε = 0.06)")
    gain_per_s: num(GAIN_RANGE, gt=0) = Field(100.0, description="observer gain K")
    threshold: Optional[num(THRESHOLD_RANGE, gt=0)] = Field(
        None, description="the paper's rule ‖r‖ > threshold, for both methods")
    false_alarm_rate: Union[str, float] = Field(
        "1/h", description="\"1/h\", \"0.01/s\", \"1e-6/sample\" or a number per second; in (0, 1) "
        "per sample")
    quiet_window_s: Optional[vector(2, ge=0)] = Field(
        None, description="[t0, t1]: estimate the residual's covariance from this contact-free stretch")

    @model_validator(mode="after")
    def _window(self):
        w = self.quiet_window_s
        if w is not None and not w[1] > w[0]:
            raise fail("quiet_window_s", f"expected [t0, t1] with t0 < t1, got {list(w)}")
        return self


class Hold(Model):
    """``[hold]`` (static scenes): each point is held for hold_s, read over the last window_s."""

    hold_s: num(gt=0) = Field(0.15, description="hold time")
    window_s: num(gt=0) = Field(0.08, description="averaging window at its end (≤ hold_s)")

    @model_validator(mode="after")
    def _window(self):
        if self.window_s > self.hold_s:
            raise fail("window_s", f"must be ≤ hold_s = {self.hold_s}, got {self.window_s}")
        return self


class Load(Model):
    """``[[load]]`` (static_loading): masses hung at points of one link."""

    link: integer(ge=1) = Field(description="link number, 1..N")
    mass_kg: vector(None, ge=0) = Field(description="masses, one hold each")
    alpha: vector(None, ge=0, le=1) = Field(description="positions along the link, 0..1")


class Grid(Model):
    """``[grid]`` (posture_sweep, two links): count × count postures."""

    q1_rad: vector(2) = Field(description="[first, last] of joint 1")
    q2_rad: vector(2) = Field(description="[first, last] of joint 2")
    count: integer(ge=1) = Field(10, description="postures per joint")


class Contact(Model):
    """``[contact]`` (posture_sweep): the contact points and the force."""

    links: vector() = Field(description="link numbers, 1..N")
    alpha: vector(None, ge=0, le=1) = Field(description="positions along the links, 0..1")
    magnitude_N: num(gt=0) = Field(description="force magnitude")
    direction_rad: num() = Field(description="force direction from +x")


class Flexure(Model):
    """``[flexure]``: where the strain per N·m comes from."""

    design: Optional[str] = Field(None, description="a flexure design (run through the FEM)")
    strain_per_Nm: Optional[num(gt=0)] = Field(None, description="or the gauge strain per N·m")

    @model_validator(mode="after")
    def _one(self):
        if self.design is not None and self.strain_per_Nm is not None:
            raise fail("strain_per_Nm", "give either a flexure design or a strain_per_Nm, not both")
        return self


class SensorRef(Model):
    """``[sensor]``: the bridge/amplifier/ADC."""

    file: Optional[str] = Field(None, description="a sensor file (beside the scene or in scenes/)")
    true_gain_factor: num(gt=0) = Field(1.0, description="the real sensor's gain over its model "
                                        "(1.05: 5 % more sensitive than calibrated)")


class Calibration(Model):
    """``[calibration]``: a stored calibration, or a simulated loading session fitted with emcee."""

    file: Optional[str] = Field(None, description="a calibration JSON (beside the scene or in "
                                "calibration/data/)")
    masses_g: vector(None, MASS_RANGE_G, gt=0) = Field(
        (10.0, 20.0, 50.0, 100.0, 200.0, 300.0, 500.0, 700.0, 850.0, 1000.0),
        description="session: load levels (at least 3)")
    lever_arm_m: num(LEVER_ARM_RANGE_M, gt=0) = Field(0.205, description="session: lever arm")
    repeats: integer(ge=1, le=10_000) = Field(3, description="session: repeats of each level")
    n_avg: integer(ge=1, le=10_000_000) = Field(256, description="session: ADC samples per reading")
    seed: integer(ge=0) = Field(0, description="session: seed")

    @property
    def session(self) -> bool:
        """A simulated session: any session key given, and no file."""
        return self.file is None and bool(self.model_fields_set & set(SESSION_KEYS))

    @model_validator(mode="after")
    def _consistent(self):
        given = sorted(self.model_fields_set & set(SESSION_KEYS))
        if self.file is not None and given:
            raise fail(given[0], "give either a calibration file or a simulated session, not both")
        if len(self.masses_g) < 3:
            raise fail("masses_g", f"need at least 3 load levels, got {len(self.masses_g)}")
        n = len(self.masses_g) * self.repeats * self.n_avg
        if self.session and n > MAX_SESSION_SAMPLES:   # the simulated session holds every code at once
            raise fail("n_avg", f"{len(self.masses_g)} masses × {self.repeats} repeats × n_avg "
                       f"{self.n_avg} = {n:.3g} ADC samples ({8 * n / 2**30:.3g} GiB) to simulate, "
                       f"above {MAX_SESSION_SAMPLES:.0e}; lower n_avg or repeats")
        return self


class Source(Model):
    """``[source]``: a recorded log instead of the simulation."""

    log: Optional[str] = Field(None, description="a recorded CSV log (beside the scene or in samples/)")
    counts_columns: list[str] = Field([], description="its columns holding raw sensor readings")
    reading_unit: Literal["counts", "mV"] = Field("counts", description="what those columns hold")


class Outputs(Model):
    """``[outputs]``: what to compute."""

    want: list[one_of(WANTABLE)] = Field([], description="results wanted (the planner runs what they need)")
    reports: Optional[list[str]] = Field(None, min_length=1, description="report areas "
                                         "(torquebench/reports/<area>.py; default: every area the scene feeds)")
    dir: Optional[str] = Field(None, description="where reports go (default ./out/<scene name>)")
    regenerate_shipped: bool = Field(False, description="may write the shipped reports/")

    @model_validator(mode="after")
    def _about_reports(self):
        given = sorted(self.model_fields_set & {"reports", "dir", "regenerate_shipped"})
        if given and "report" not in self.want:
            raise fail(given[0], "is about reports, but outputs.want has no \"report\"")
        return self


class SceneFile(Model):
    """A planar scene (``run SCENE``, ``simulate``, ``sweep``, ``compare``)."""

    name: Optional[str] = Field(None, description="label (default: the file's stem)")
    description: str = Field("", description="free text")
    kind: Literal[KINDS] = Field("dynamic", description="dynamic, static_loading or posture_sweep")
    robot: Union[str, RobotRef] = Field("paper_leg.toml", description="the robot file (beside the "
                                        "scene or in robots/), or a [robot] table")
    base: Literal["floating", "fixed", "rigid"] = Field(
        "floating", description="floating: on the mount springs; fixed: a stiff mount emulating the "
        "FT sensor; rigid: welded (the FT reads the constraint wrench)")
    duration_s: num(_r(sim.SimConfig, "duration_s"), gt=0) = Field(1.5, description="simulated time")
    controller: Optional[Controller] = Field(None, description="dynamic: the joint servo (required)")
    poke: list[Poke] = Field([], description="dynamic: external forces")
    ground: Optional[Ground] = Field(None, description="dynamic: a floor")
    sensors: Sensors = Field(Sensors(), description="sampling and noise")
    integrator: Integrator = Field(Integrator(), description="dynamic: the ODE solver")
    mount: Optional[Mount] = Field(None, description="dynamic: the base's springs")
    estimator: Estimator = Field(Estimator(), description="observer and detector")
    hold: Hold = Field(Hold(), description="static scenes: hold times")
    q_rad: Optional[vector()] = Field(None, description="static_loading: the held posture, one per joint")
    load: list[Load] = Field([], description="static_loading: the masses")
    grid: Optional[Grid] = Field(None, description="posture_sweep: the postures")
    contact: Optional[Contact] = Field(None, description="posture_sweep: contacts and force")
    flexure: Flexure = Field(Flexure(), description="strain per N·m")
    sensor: SensorRef = Field(SensorRef(), description="the sensor electronics")
    calibration: Calibration = Field(Calibration(), description="calibration")
    source: Source = Field(Source(), description="a recorded log")
    outputs: Outputs = Field(Outputs(), description="what to compute")

    @model_validator(mode="after")
    def _consistent(self):
        rob = self.robot if isinstance(self.robot, RobotRef) else None
        if rob is not None and self.kind != "dynamic" and (rob.true_parameters or rob.perturbation is not None):
            raise fail("robot", "true_parameters / perturbation: only a dynamic scene simulates a "
                       "robot other than its file")
        self._rate()
        self._source()
        if self.kind == "dynamic" and self.source.log is not None:
            given = [k for k in SIM_KEYS if k in self.model_fields_set]
            if given:
                raise fail(given[0], "a scene with a recorded log (source.log) has no simulation keys")
        elif self.kind == "dynamic":
            self._dynamic()
        elif self.kind == "static_loading":
            if self.q_rad is None:
                raise fail("q_rad", "missing field")
            if not self.load:
                raise fail("load", "expected at least one [[load]] table")
        elif self.grid is None or self.contact is None:
            raise fail("grid" if self.grid is None else "contact", "missing field")
        return self

    def _rate(self):
        from estimator.noise import parse_rate, per_sample_rate
        from userio.errors import InputError

        raw = self.estimator.false_alarm_rate
        try:
            per_sample_rate(*parse_rate(str(raw), "x"), 1.0 / self.sensors.sample_rate_Hz, "x")
        except InputError as exc:
            raise fail("estimator.false_alarm_rate", str(exc).removeprefix("x: ")) from None

    def _source(self):
        so, cal = self.source, self.calibration
        cols = so.counts_columns
        if cols and so.log is None:
            raise fail("source.counts_columns", "counts columns need a recorded log (source.log)")
        if cols and cal.file is None and not cal.session:
            raise fail("source.counts_columns", "raw ADC counts need a [calibration] to become torques")
        if "reading_unit" in so.model_fields_set and not cols:
            raise fail("source.reading_unit", "says what source.counts_columns hold; there are none")
        if cols and cal.session and so.reading_unit != "counts":
            raise fail("source.reading_unit", f"the simulated calibration session reads ADC counts, "
                       f"but source.counts_columns hold {so.reading_unit!r}")

    def _dynamic(self):
        if self.controller is None:
            raise fail("controller", "missing field")
        if self.ground is not None and self.base == "rigid":
            raise fail("ground", "a ground contact needs base = \"floating\" or \"fixed\"")
        if self.mount is not None and self.base == "rigid":
            raise fail("mount", "a rigid base has no mount springs")
        spans = []
        for i, p in enumerate(self.poke, start=1):
            t_off = self.duration_s if p.t_off_s is None else p.t_off_s
            if t_off < p.t_on_s:
                raise fail(f"poke[{i}].t_off_s", f"must be ≥ t_on_s = {p.t_on_s}, got {t_off}")
            if p.t_on_s >= self.duration_s:
                raise fail(f"poke[{i}].t_on_s", f"{p.t_on_s:g} s starts at or after the end of the "
                           f"simulation (duration_s = {self.duration_s:g} s): the poke would never "
                           "act; start it earlier or lengthen duration_s")
            if t_off > p.t_on_s:
                spans.append((p.t_on_s, t_off + p.ramp_s, i))
        spans.sort()
        for (a0, a1, i), (b0, b1, j) in zip(spans, spans[1:]):
            if b0 < a1:
                raise fail(f"poke[{j}].t_on_s", f"overlaps poke[{i}] (one contact at a time: the "
                           "truth file holds one)")
        f = self.controller.frequency_Hz
        if f is not None:
            nyq = 0.5 * self.sensors.sample_rate_Hz
            f_max = float(np.max(np.asarray(f, float)))          # every joint's every harmonic
            if f_max >= nyq:
                raise fail("controller.frequency_Hz", f"{f_max:g} Hz is at or above the log's "
                           f"Nyquist frequency {nyq:g} Hz (sensors.sample_rate_Hz = "
                           f"{self.sensors.sample_rate_Hz:g}): the motion could not be sampled")
