"""Model uncertainty on a URDF robot's 3-D logs: the model-error term (estimator.model_error) with
the UrdfModel's regressor, and the identification (estimator.identification) of a robot simulated
with other inertial parameters than its file (``UrdfModel.perturbed``)."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("pinocchio")

from scipy.special import chdtri  # noqa: E402

from estimator import identification as ident  # noqa: E402
from estimator.model import ModelUncertainty  # noqa: E402
from estimator.model_error import ModelTerm, statistic_numpy  # noqa: E402
from estimator.spatial import noise as snoise  # noqa: E402
from estimator.spatial.model import UrdfModel  # noqa: E402
from estimator.spatial.observer import residual  # noqa: E402
from estimator.spatial.robot import load_spatial_robot  # noqa: E402
from estimator.spatial.sim import SimSpec, simulate  # noqa: E402

DECLARED = ModelUncertainty(mass_rel=0.05, inertia_rel=0.10, com_m=0.003)
ALPHA = 1e-3                                   # false alarms per sample


@pytest.fixture(scope="module")
def leg():
    return UrdfModel(load_spatial_robot("robots/quadruped_leg.toml"))


def run_log(model, seconds, seed, amplitude=(0.3, 0.5, 0.6), freq=1.5):
    """A contact-free 500 Hz log of ``model`` tracking sines, with the default sensor noise."""
    spec = SimSpec(duration_s=seconds, sample_rate_Hz=500.0, substeps=4,
                   q0_rad=np.array([0.2, 0.6, -1.2]), amplitude_rad=np.array(amplitude),
                   frequency_Hz=freq, noise=snoise.default_noise(model), seed=seed)
    return simulate(model.robot, spec)[0]


@pytest.fixture(scope="module")
def true_robot(leg):
    return leg.perturbed(DECLARED, seed=1)


@pytest.fixture(scope="module")
def short_log(true_robot):
    return run_log(true_robot, 0.8, seed=11)


def flags(model, log, cov):
    """Samples whose χ² (the residual of ``model``, R = R_noise [+ Φ Σ_θ Φᵀ]) exceeds the α quantile."""
    dt = float(log.t[1] - log.t[0])
    r = residual(model, log.t, log.q, log.v, log.tau_meas(model))
    stride = 10
    idx = np.arange(0, len(log.t), stride)
    Rn = snoise.residual_covariance(model, log.q[idx], log.v[idx], snoise.default_noise(model), 100.0, dt)
    blk = np.arange(len(log.t)) // stride
    if cov is None:
        s = statistic_numpy(r.T, np.zeros((len(r), model.n_v, 0)), Rn, blk)
    else:
        s, _ = ModelTerm(model, cov, 100.0, dt).statistic(log.t, log.q, log.v, r.T, Rn, blk)
    return int(np.sum(s > chdtri(model.n_v, ALPHA))), len(s)


def test_phi_is_the_residuals_exact_sensitivity_on_a_3d_log(leg, true_robot, short_log):
    """The observer is linear in θ: r(θ_file) − r(θ_true) = Φ (θ_file − θ_true), with Φ from the
    URDF regressor through ModelTerm's filter (no fused kernel: the generic path)."""
    log = short_log
    tau = log.tau_meas(leg)
    ra = residual(leg, log.t, log.q, log.v, tau)
    rb = residual(true_robot, log.t, log.q, log.v, tau)
    term = ModelTerm(leg, np.eye(len(leg.parameter_names)), 100.0, float(log.t[1] - log.t[0]))
    _, phi = term.statistic(log.t, log.q, log.v, ra.T, np.eye(leg.n_v)[None], np.zeros(len(log.t), np.int64))
    pred = np.einsum("tnk,k->tn", phi, leg.parameters() - true_robot.parameters())
    assert np.abs(ra - rb).max() > 0.1                    # N: a real model error
    np.testing.assert_allclose(ra - rb, pred, atol=1e-9 * np.abs(ra - rb).max())


def test_declared_uncertainty_explains_the_model_error(leg, short_log, tmp_path):
    """On a contact-free log of a robot drawn from the declared uncertainty: the file's nominal
    model flags most samples; with the file's [model_uncertainty] (model_covariance) in R_k the
    detector keeps its rate (α T = 0.4 expected here)."""
    import shutil

    shutil.copy("robots/quadruped_leg.urdf", tmp_path / "quadruped_leg.urdf")
    (tmp_path / "leg.toml").write_text(open("robots/quadruped_leg.toml").read()
                                       + "\n[model_uncertainty]\nmass_rel = 0.05\ninertia_rel = 0.1\n"
                                         "com_m = 0.003\n")
    declared = UrdfModel(load_spatial_robot(tmp_path / "leg.toml"))
    cov, source = declared.model_covariance()
    assert source.startswith("declared")
    n_nom, T = flags(leg, short_log, None)
    n_dec, _ = flags(declared, short_log, cov)
    assert n_nom > 0.5 * T
    assert n_dec <= 3


@pytest.mark.slow
def test_identified_model_recovers_the_robot_and_stops_the_flags(leg, true_robot, short_log):
    """Identify on a 2 s excitation log of the perturbed robot (prior: the declared uncertainty):
    consistent, χ²/dof ≈ 1, every parameter within 4 posterior σ of the truth; on another log
    the identified model with its posterior covariance keeps the detector's rate."""
    log = run_log(true_robot, 2.0, seed=1, amplitude=(0.4, 0.8, 0.8), freq=1.3)
    noise = snoise.default_noise(leg)
    eqs = ident.window_equations(leg, log.t, log.q, log.v, log.tau_meas(leg), noise, window_s=0.01)
    res = ident.identify(leg, [eqs], leg.parameter_covariance(DECLARED))
    assert leg.consistency_problems(res.theta) == []
    assert 0.7 < res.statistics["chi2_per_dof"] < 1.5
    sd = np.sqrt(np.diag(res.covariance))
    z = (res.theta - true_robot.parameters()) / sd
    assert np.abs(z).max() < 4.0
    err_before = np.abs(leg.parameters() - true_robot.parameters()) / sd
    assert np.median(np.abs(z)) < np.median(err_before)
    identified = leg.with_parameters(res.theta)
    n_id, T = flags(identified, short_log, res.covariance)
    assert n_id <= 3 and flags(leg, short_log, None)[0] > 0.5 * T


@pytest.mark.slow
def test_identify_command_on_a_urdf_robot(leg, true_robot, short_log, tmp_path):
    """``torquebench identify LOG --robot leg.toml`` on a 3-D log writes IDENTIFIED.urdf and
    IDENTIFIED.toml; they read back with the fitted parameters and the posterior covariance,
    which keeps the detector's rate on another log of the same robot."""
    import json
    import shutil

    from estimator.spatial.logs import noise_text, write_spatial_log
    from tests.test_identification import _tb

    log = run_log(true_robot, 2.0, seed=1, amplitude=(0.4, 0.8, 0.8), freq=1.3)
    path = tmp_path / "exc.csv"
    write_spatial_log(log, leg.robot, path)
    (tmp_path / "exc.noise.toml").write_text(noise_text(snoise.default_noise(leg)))
    shutil.copy("robots/quadruped_leg.urdf", tmp_path / "quadruped_leg.urdf")
    decl = tmp_path / "leg.toml"
    decl.write_text(open("robots/quadruped_leg.toml").read() + "\n[model_uncertainty]\nmass_rel = "
                    "0.05\ninertia_rel = 0.1\ncom_m = 0.003\n")
    out = tmp_path / "out" / "leg_id.toml"
    res = _tb("identify", path, "--robot", decl, "--out", out, "--window", "0.01", "--json")
    assert res.returncode == 0, res.stderr
    summary = json.loads(res.stdout)
    assert 0.7 < summary["statistics"]["chi2_per_dof"] < 1.5
    assert "log declaration" in summary["logs"][0]["noise"] or "exc.noise" in summary["logs"][0]["noise"]
    back = UrdfModel(load_spatial_robot(out))
    assert (tmp_path / "out" / "leg_id.urdf").is_file() and back.name == "quadruped_leg_identified"
    theta = np.array([p["identified"] for p in summary["parameters"]])
    np.testing.assert_allclose(back.parameters(), theta, rtol=1e-9, atol=1e-13)
    cov, source = back.model_covariance()
    assert source.startswith("identification of quadruped_leg_identified from")
    n_id, T = flags(back, short_log, cov)
    assert n_id <= 3
    again = _tb("identify", path, "--robot", decl, "--out", out)
    assert again.returncode == 2 and "exists" in again.stderr and again.stderr.count("\n") == 1


def test_3d_estimate_carries_the_files_model_uncertainty(leg, short_log, tmp_path):
    """``estimate`` on a 3-D contact-free log of a robot drawn from the declared uncertainty: the
    nominal file (none declared) reports contact on most samples; the same URDF with a declared
    [model_uncertainty] (R_k = R_noise + Φ_k Σ_θ Φ_kᵀ in the 3-D stream) on none; the option
    ``--model-uncertainty none`` turns it off again."""
    import json
    import shutil

    from estimator.spatial.logs import noise_text, write_spatial_log
    from tests.test_identification import _tb

    path = tmp_path / "run.csv"
    write_spatial_log(short_log, leg.robot, path)
    (tmp_path / "run.noise.toml").write_text(noise_text(snoise.default_noise(leg)))
    shutil.copy("robots/quadruped_leg.urdf", tmp_path / "quadruped_leg.urdf")
    decl = tmp_path / "leg.toml"
    decl.write_text(open("robots/quadruped_leg.toml").read() + "\n[model_uncertainty]\nmass_rel = "
                    "0.05\ninertia_rel = 0.1\ncom_m = 0.003\n")
    runs = {}
    for key, robot, extra in (("nominal", "robots/quadruped_leg.toml", ()), ("declared", decl, ()),
                              ("off", decl, ("--model-uncertainty", "none"))):
        res = _tb("estimate", path, "--robot", robot, "--json", *extra)
        assert res.returncode == 0, res.stderr
        runs[key] = json.loads(res.stdout)
    T = runs["nominal"]["samples"]
    assert runs["nominal"]["contact_samples"] > 0.5 * T
    assert runs["declared"]["contact_samples"] == 0
    assert runs["declared"]["model_uncertainty_source"].startswith("declared model uncertainty")
    assert runs["off"]["contact_samples"] > 0.5 * T


@pytest.mark.slow
def test_model_term_keeps_the_poke_and_does_not_depend_on_chunks(leg, true_robot):
    """With the declared uncertainty in R_k a 4 N poke on the shank of the perturbed robot is still
    detected and located on the shank; fed in uneven chunks, the stream gives the same frame."""
    from estimator.spatial.logs import SpatialLog
    from estimator.spatial.pipeline import estimate_log
    from estimator.spatial.sim import Poke

    poke = Poke("shank", np.array([0.012, 0.0, -0.12]), np.array([-4.0, 1.0, 2.0]), 0.4, 0.6, 0.02)
    spec = SimSpec(duration_s=0.8, sample_rate_Hz=500.0, substeps=4, q0_rad=np.array([0.2, 0.6, -1.2]),
                   amplitude_rad=np.array([0.3, 0.5, 0.6]), frequency_Hz=1.5,
                   noise=snoise.default_noise(leg), seed=5, pokes=[poke])
    log, truth, _ = simulate(true_robot.robot, spec)
    cov = leg.parameter_covariance(DECLARED)
    dt = float(log.t[1] - log.t[0])
    whole = estimate_log(leg, [log], dt, model_cov=cov, model_source="declared")
    cuts = [0, 37, 150, 151, 260, len(log.t)]
    parts = [SpatialLog(log.t[a:b], log.q[a:b], log.v[a:b], log.tau_Nm[a:b], log.wrench[a:b], log.floating)
             for a, b in zip(cuts[:-1], cuts[1:])]
    chunked = estimate_log(leg, parts, dt, model_cov=cov, model_source="declared")
    f, g = whole.frame, chunked.frame
    np.testing.assert_array_equal(f["contact"].to_numpy(), g["contact"].to_numpy())
    np.testing.assert_allclose(f["rnorm"].to_numpy(), g["rnorm"].to_numpy(), rtol=1e-9)
    on = (log.t >= 0.45) & (log.t < 0.6)
    c = f["contact"].to_numpy().astype(bool)
    assert c[on].mean() > 0.8 and c[log.t < 0.38].sum() == 0
    assert [iv["link"] for iv in whole.intervals] == ["shank"]
