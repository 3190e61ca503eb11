"""`torquebench identify` and estimator.identification on logs built by inverse dynamics of a robot
whose inertial data differ from the file (exact dynamics, seeded sensor noise): recovery within
the stated σ, the unexcited directions, physical consistency, contacts excluded or refused,
bad input in one line, and the identified file read back by estimate and propagate."""

import json
from pathlib import Path

import numpy as np
import pytest

from estimator import identification as ident
from estimator import inertial
from userio.errors import InputError
from estimator.excitation import Fourier
from estimator.log import SensorLog
from estimator.model import ModelUncertainty
from estimator.noise import NoiseModel
from estimator.robot import load_robot, paper_leg
from estimator.synthetic import inverse_dynamics_log
from torquebench.scenes import load_scene, scene_path

ROOT = Path(__file__).resolve().parents[1]
NOMINAL = paper_leg()
TRUE = inertial.perturbed(NOMINAL, ModelUncertainty(0.05, 0.10, 0.003), 7)
NOISE = NoiseModel([0.005], [0.1, 0.1, 0.01])
SIG = np.r_[0.1, 0.1, 0.01, 0.005, 0.005]


def excitation_log(robot=TRUE, duration=12.0, seed=0, contact=None, move=True, sway=True):
    """The shipped excitation's reference (perfect tracking) with a small base sway, realized by
    inverse dynamics of ``robot``; ``contact`` = (t0, t1, link, α, F) adds a force."""
    ctrl = load_scene(scene_path("identification_excitation")).sim.controller
    t = np.arange(int(duration * 1000) + 1) / 1000.0
    qj, dqj, ddqj = Fourier.from_controller(ctrl).evaluate(t)
    if not move:
        qj, dqj, ddqj = qj[:1] + 0 * qj, 0 * dqj, 0 * ddqj
    w = 2 * np.pi * np.array([2.3, 3.1, 4.7])
    A = np.array([0.002, 0.002, 0.01]) * sway
    qb, dqb, ddqb = A * np.sin(w * t[:, None]), A * w * np.cos(w * t[:, None]), -A * w * w * np.sin(w * t[:, None])
    q, dq, ddq = (np.concatenate(x, axis=1) for x in ((qb, qj), (dqb, dqj), (ddqb, ddqj)))
    link, alpha, F, active = 1, 0.5, [0.0, 0.0], np.zeros(len(t), bool)
    if contact is not None:
        t0, t1, link, alpha, F = contact
        active = (t >= t0) & (t < t1)
    log, _ = inverse_dynamics_log(robot, t, q, dq, ddq, link, alpha, F, active=active)
    e = np.random.default_rng(seed).standard_normal((len(t), 5)) * SIG
    return SensorLog(t=t, q=q, dq=dq, tau_Nm=log.tau_Nm + e[:, 3:], wrench=log.wrench + e[:, :3])


def equations(log, robot=NOMINAL):
    return ident.window_equations(robot, log.t, log.q, log.dq, log.tau_meas, NOISE, None, 0.005,
                                  source="log.csv")


PRIOR = NOMINAL.parameter_covariance(ModelUncertainty.uniform(0.3))


@pytest.fixture(scope="module")
def fit():
    return ident.identify(NOMINAL, [equations(excitation_log())], PRIOR)


def test_identified_parameters_within_their_stated_sigma(fit):
    z = (fit.theta - TRUE.parameters()) / np.sqrt(np.diag(fit.covariance))
    print("z:", np.round(z, 2), "unexcited:", fit.unexcited, fit.statistics["chi2_per_dof"])
    assert np.all(np.abs(z) < 3)
    assert 0.9 < fit.statistics["chi2_per_dof"] < 1.1            # noise as declared
    assert fit.statistics["whitened_rms_after"] < 1.05 < 2 < fit.statistics["whitened_rms_before"]
    # first moments and inertias are far better known than the prior (the masses individually
    # need base motion: they are identified in combinations, marginally less)
    sd, sd0 = np.sqrt(np.diag(fit.covariance)), np.sqrt(np.diag(PRIOR))
    moments = [i for i, n in enumerate(fit.names) if n.endswith(("mc_par", "mc_perp", "I_joint"))]
    assert np.all(sd[moments] < 0.2 * sd0[moments])
    assert NOMINAL.consistency_problems(fit.theta) == []


def test_unexcited_directions_are_named_and_kept_near_nominal():
    """A base that never turns (held in its FT sensor) says nothing about the base inertia:
    named, and kept at its nominal value with its prior σ. A leg that does not move is refused."""
    log = excitation_log(sway=False)
    res = ident.identify(NOMINAL, [equations(log)], PRIOR)
    i = res.names.index("base.I")
    assert "base.I" in res.unexcited and res.statistics["excited_directions"] < 10
    assert res.theta[i] == pytest.approx(NOMINAL.base_inertia_kgm2, rel=1e-6)
    assert np.sqrt(res.covariance[i, i]) == pytest.approx(np.sqrt(PRIOR[i, i]), rel=1e-3)
    with pytest.raises(InputError, match="the joints do not move"):
        ident.identify(NOMINAL, [equations(excitation_log(move=False))], PRIOR)


def test_a_contact_is_excluded_and_named():
    log = excitation_log(contact=(4.0, 4.6, 2, 0.5, [1.5, 1.0]))
    fit = ident.identify(NOMINAL, [equations(log)], PRIOR)
    (span,) = fit.excluded["log.csv"]
    assert 3.95 <= span[0] <= 4.0 and 4.6 <= span[1] <= 4.65
    z = (fit.theta - TRUE.parameters()) / np.sqrt(np.diag(fit.covariance))
    assert np.all(np.abs(z) < 3)
    long = excitation_log(contact=(2.0, 6.0, 2, 0.5, [1.5, 1.0]))
    with pytest.raises(InputError, match=r"log.csv: contact or unmodelled force in 1\.98.*–6\.01"):
        ident.identify(NOMINAL, [equations(long)], PRIOR)


def test_the_constrained_fit_stays_physical():
    """An unconstrained optimum with a negative inertia about the centre of mass is moved to the
    nearest consistent θ in the fit's metric."""
    theta0 = NOMINAL.parameters()
    bad = theta0.copy()
    bad[9] = 0.5 * bad[6] * NOMINAL.com_m[1] ** 2                   # link 2: I_o < m r²
    H = np.linalg.inv(PRIOR) * 1e6
    theta, active = ident._constrained(NOMINAL, H, bad, theta0, PRIOR)
    assert NOMINAL.consistency_problems(bad) and NOMINAL.consistency_problems(theta) == []
    assert active == ["link 2: inertia about the COM > 0"]
    assert (theta - bad) @ H @ (theta - bad) < (theta0 - bad) @ H @ (theta0 - bad)


# ------------------------------------------------------------------------- the command
def _write(log, path):
    from estimator.sim.output import log_files
    from userio.files import write_files_atomic

    T = len(log.t)
    truth = {"t": log.t, "link": np.zeros(T, int), **{k: np.full(T, np.nan) for k in
                                                       ("alpha", "Fx", "Fz", "px", "pz")}}
    write_files_atomic(log_files(path, log, truth, path.with_name(path.stem + ".truth.csv"), NOISE))
    return path


def _tb(*args):
    """``torquebench ARGS`` in process (exit code, stdout, stderr): the CLI's own error handling,
    without a fresh interpreter's start-up."""
    import contextlib
    import io
    from types import SimpleNamespace

    from torquebench.cli import main

    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            code = main([str(a) for a in args])
        except SystemExit as exc:                  # argparse: a bad option
            code = exc.code
    return SimpleNamespace(returncode=code, stdout=out.getvalue(), stderr=err.getvalue())


@pytest.fixture(scope="module")
def identified(tmp_path_factory):
    d = tmp_path_factory.mktemp("ident")
    log = _write(excitation_log(duration=10.0, seed=3), d / "exc.csv")
    proc = _tb("identify", log, "--out", d / "id.toml", "--json")
    assert proc.returncode == 0, proc.stderr
    return d, json.loads(proc.stdout)


def test_cli_writes_a_robot_file_the_other_commands_read(identified):
    d, out = identified
    robot = load_robot(d / "id.toml")
    t = robot.identification
    assert t["logs"][0]["sha256"] == __import__("hashlib").sha256((d / "exc.csv").read_bytes()).hexdigest()
    assert t["parameter_names"] == list(NOMINAL.parameter_names)
    assert np.allclose(np.asarray(t["covariance"]), np.asarray(t["covariance"]).T)
    assert out["statistics"]["chi2_per_dof"] < 1.2 and out["unexcited"]
    assert "log declaration exc.noise.toml" in out["logs"][0]["noise"]
    cov, source = robot.model_covariance()
    assert "identification" in source and cov.shape == (10, 10)
    est = _tb("estimate", d / "exc.csv", "--robot", d / "id.toml", "--json")
    assert est.returncode == 0, est.stderr
    summary = json.loads(est.stdout)
    assert "identification of" in summary["model_uncertainty_source"]
    assert summary["contact_samples"] < 0.001 * summary["samples"]
    prop = _tb("propagate", "--robot", d / "id.toml", "--grid", "2", "--draws", "50", "--json")
    assert prop.returncode == 0, prop.stderr
    assert "identification" in json.loads(prop.stdout)["model_uncertainty_source"]


def _one_line_exit_2(proc, *fragments):
    assert proc.returncode == 2, proc.stderr
    assert len(proc.stderr.strip().splitlines()) == 1, proc.stderr
    for f in fragments:
        assert f in proc.stderr, proc.stderr


def test_bad_input_is_one_line(tmp_path, identified):
    d, _ = identified
    short = _write(excitation_log(duration=0.1), tmp_path / "short.csv")
    _one_line_exit_2(_tb("identify", short, "--out", tmp_path / "a.toml"), "short.csv", "too short")
    still = _write(excitation_log(duration=2.0, move=False), tmp_path / "still.csv")
    _one_line_exit_2(_tb("identify", still, "--out", tmp_path / "a.toml"), "still.csv", "do not move")
    text = (d / "exc.csv").read_text().splitlines()
    for i in range(2000, 2050):                          # a NaN stretch in the torques
        f = text[i].split(",")
        f[-4] = "nan"
        text[i] = ",".join(f)
    gap = tmp_path / "gap.csv"
    gap.write_text("\n".join(text) + "\n")
    _one_line_exit_2(_tb("identify", gap, "--out", tmp_path / "a.toml"), "gap.csv", "lines 2001–2050",
                     "cannot bridge")
    three = tmp_path / "three.toml"
    three.write_text((ROOT / "robots" / "paper_leg.toml").read_text() +
                     "\n[[link]]\nlength_m = 0.1\ncom_m = 0.05\nmass_kg = 0.05\ninertia_kgm2 = 1e-4\n")
    _one_line_exit_2(_tb("identify", d / "exc.csv", "--robot", three, "--out", tmp_path / "a.toml"),
                     "exc.csv")
    _one_line_exit_2(_tb("identify", d / "exc.csv", "--out", d / "id.toml"), "exists", "--force")
    _one_line_exit_2(_tb("identify", d / "exc.csv", "--out", tmp_path / "a.toml", "--prior", "0"),
                     "--prior")


def test_declared_timing_sets_the_quadrature():
    """Forces read as interval means (an integrating ADC): declared `mean`, the fit's residual is
    noise (χ²/dof ≈ 1) and θ within its σ; read as if instantaneous, the window sums are off by
    half a step of the force's change and the fit says so (χ²/dof far above 1)."""
    from estimator.timing import uniform
    from torquebench.reports.detection import simulated_log

    log = simulated_log(TRUE, 6.0, "moving", readout="mean", seed=4)
    fits = {}
    for kind in ("mean", "instant"):
        eq = ident.window_equations(NOMINAL, log.t, log.q, log.dq, log.tau_meas, NOISE,
                                    uniform(kind, 2), 0.005, source="log.csv")
        fits[kind] = ident.identify(NOMINAL, [eq], PRIOR)
    good, bad = fits["mean"], fits["instant"]
    z = (good.theta - TRUE.parameters()) / np.sqrt(np.diag(good.covariance))
    print("χ²/dof mean", good.statistics["chi2_per_dof"], "instant", bad.statistics["chi2_per_dof"])
    assert good.statistics["chi2_per_dof"] < 1.2 and np.all(np.abs(z) < 3)
    assert bad.statistics["chi2_per_dof"] > 2 * good.statistics["chi2_per_dof"]
