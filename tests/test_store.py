"""Calibration store: atomic, versioned, verified; the sensor model's torque and uncertainty."""

import json

import numpy as np
import pytest

import calibration
from userio.errors import InputError
from calibration.fit import fit_session
from calibration.session import write_session
from calibration.simulate import paper_session
from calibration.store import calibration_payload, save


@pytest.fixture(scope="module")
def stored(tmp_path_factory):
    d = tmp_path_factory.mktemp("store")
    s = paper_session(1, unload=True, hysteresis_Nm=0.005, repeats=3)
    data = write_session(s, d / "session.csv")
    from calibration.session import read_session
    s = read_session(data)
    fit = fit_session(s, "hysteresis", seed=2)
    path = save(calibration_payload(fit, s), d / "cal.json")
    return d, data, s, fit, path


def test_document_contents(stored):
    d, data, s, fit, path = stored
    doc = json.loads(path.read_text())
    assert doc["schema"] == "torquebench.calibration" and doc["schema_version"] == 1
    assert set(doc["coefficients"]) == {"slope", "offset", "hysteresis"}
    for n in ("slope", "offset", "hysteresis", "sigma"):
        p = doc["posterior"][n]
        assert p["p16"] < p["p50"] < p["p84"] and p["std"] > 0
    assert np.array(doc["covariance"]["matrix"]).shape == (3, 3)
    assert np.array(doc["samples"]["values"]).shape[1] == 4
    assert doc["data"]["sha256"] == s.sha256 and doc["diagnostics"]["converged"] is True
    assert doc["lever_arm_m"] == 0.205 and doc["reading_unit"] == "mV"


def test_never_overwrites_without_force(stored):
    d, data, s, fit, path = stored
    before = path.read_bytes()
    p2 = save(calibration_payload(fit, s), path)
    p3 = save(calibration_payload(fit, s), path)
    assert path.read_bytes() == before
    assert p2.name == "cal.v2.json" and p3.name == "cal.v3.json"
    p4 = save(calibration_payload(fit, s), p2, force=True)
    assert p4 == p2 and calibration.load(p4).model == "hysteresis"
    assert not list(d.glob(".*tmp"))                  # no temp files left behind


def test_load_checks_schema_and_hashes(stored, tmp_path):
    d, data, s, fit, path = stored
    calibration.load(path, data_path=data)            # the right data verifies
    doc = json.loads(path.read_text())
    bad = dict(doc, coefficients={**doc["coefficients"], "slope": 1.0})
    (tmp_path / "edited.json").write_text(json.dumps(bad))
    with pytest.raises(InputError, match="content hash mismatch"):
        calibration.load(tmp_path / "edited.json")
    (tmp_path / "v9.json").write_text(json.dumps(dict(doc, schema_version=9)))
    with pytest.raises(InputError, match="schema_version"):
        calibration.load(tmp_path / "v9.json")
    (tmp_path / "junk.json").write_text("{not json")
    with pytest.raises(InputError, match="line 1: invalid JSON"):
        calibration.load(tmp_path / "junk.json")
    other = tmp_path / "other.csv"
    other.write_text(data.read_text().replace("load,0", "load,7", 1))
    with pytest.raises(InputError, match="hash mismatch"):
        calibration.load(path, data_path=other)


def test_sensor_model_torque_and_uncertainty(stored):
    d, data, s, fit, path = stored
    model = calibration.load(path)
    rng = np.random.default_rng(0)
    tau_true = np.array([0.1, 1.0, 1.9])
    S = 0.0115 / (9.81e-3 * 0.205)                    # mV per N·m (truth of the simulation)
    readings = 5.0069 + S * tau_true
    tau = model.torque(readings, direction=np.array(["load"] * 3))
    assert np.all(np.abs(tau - tau_true) < 4 * model.torque_std(readings, np.array(["load"] * 3)))
    # first-order std of the coefficient part agrees with posterior draws
    draws = model.torque_draws(readings, 20000, rng, direction=np.array(["load"] * 3))
    lin = model.torque_std(readings, np.array(["load"] * 3), include_noise=False)
    assert np.allclose(draws.std(axis=0), lin, rtol=0.1)
    # with the reading noise: draws including noise agree with the full std
    full = model.torque_draws(readings, 20000, rng, direction=np.array(["load"] * 3), include_noise=True)
    assert np.allclose(full.std(axis=0), model.torque_std(readings, np.array(["load"] * 3)), rtol=0.1)
    # unknown branch: the std covers the two-branch mixture (draws half loading, half unloading)
    mix = np.concatenate([model.torque_draws(readings, 20000, rng, direction=np.array([d] * 3),
                                             include_noise=True) for d in ("load", "unload")])
    assert np.allclose(mix.std(axis=0), model.torque_std(readings), rtol=0.1)
    assert np.allclose(mix.mean(axis=0), model.torque(readings), atol=0.1 * mix.std())
    c = model.sample_coefficients(500, rng)
    assert c.shape == (500, 3)
    assert np.all(np.abs(c.mean(0) - model.coef_mean) < 4 * np.sqrt(np.diag(model.coef_cov) / 500))
    assert np.allclose(c.std(0, ddof=1), np.sqrt(np.diag(model.coef_cov)), rtol=0.15)
    sd = np.sqrt(np.diag(model.coef_cov))
    assert np.allclose(np.corrcoef(c, rowvar=False), model.coef_cov / np.outer(sd, sd), atol=0.15)


def test_quadratic_inverse_is_exact_and_flags_out_of_range():
    from calibration.model import SensorModel
    m = SensorModel(model="quadratic", coef_names=("slope", "offset", "quad"),
                    coef_mean=np.array([-0.0108, -2.3, -1e-6]), coef_cov=np.eye(3) * 1e-12,
                    sigma=0.01, samples=np.array([[-0.0108, -2.3, -1e-6]]),
                    sigma_samples=np.array([0.01]), lever_arm_m=0.2)
    mass = np.array([0.0, 10.0, 500.0, 1000.0])
    r = -0.0108 * mass - 2.3 - 1e-6 * mass**2
    assert np.allclose(m.mass_g(r), mass, atol=1e-9)
    assert np.isnan(m.mass_g(np.array([1e6])))[0]       # beyond the parabola's vertex: NaN


def test_torque_without_lever_arm_is_an_input_error():
    from calibration.model import SensorModel
    m = SensorModel(model="linear", coef_names=("slope", "offset"), coef_mean=np.array([1.0, 0]),
                    coef_cov=np.eye(2) * 1e-6, sigma=0.1, samples=np.array([[1.0, 0.0]]),
                    sigma_samples=np.array([0.1]), lever_arm_m=None)
    assert np.allclose(m.mass_g([2.0]), 2.0)
    with pytest.raises(InputError, match="lever_arm_m"):
        m.torque([1.0])


def test_shipped_calibration_verifies_against_its_session():
    from torquebench.io import REPO_ROOT
    d = REPO_ROOT / "calibration" / "data"
    model = calibration.load(d / "paper_link1_cal.json", data_path=d / "paper_link1_session.csv")
    assert model.sensor_id == "paper-link1" and model.info["diagnostics"]["converged"]
    truth = np.loadtxt(d / "paper_link1_readings.csv", delimiter=",", skiprows=2)
    tau = model.torque(truth[:, 1])
    assert np.all(np.abs(tau - truth[:, 0]) < 4 * model.torque_std(truth[:, 1]))
