"""Calibration: session validation, exact posterior, emcee vs exact, paper fits, sensor model."""

import numpy as np
import pytest

from userio.errors import InputError
from calibration.fit import fit_session
from calibration.posterior import design_matrix, exact_posterior
from calibration.session import Session, read_session, write_session
from calibration.simulate import PAPER_FITS, SessionSpec, paper_session, paper_spec, simulate_session


def _csv(tmp_path, text, name="s.csv"):
    p = tmp_path / name
    p.write_text(text)
    return p


# ---- data ----------------------------------------------------------------------------------
@pytest.mark.parametrize("text,match", [
    ("mass_g,reading\n10,1\n-5,2\n", r"line 3: column 'mass_g': negative mass"),
    ("mass,reading\n10,1\n20,2\n", r"line 1: missing required column 'mass_g'"),
    ("mass_g,reading\n10,1\n20,abc\n", r"line 3: column 'reading': 'abc' is not a finite number"),
    ("mass_g,reading\n10,1\n10,2\n", r"single load level"),
    ("# reading_unit=mV\nmass_g,reading,direction\n10,1,load\n20,2,sideways\n",
     r"line 4: column 'direction'"),
    ("mass_g,reading,lever_arm_m\n10,1,0.2\n20,2,0.3\n", r"line 3: column 'lever_arm_m'"),
    ("", r"empty file"),
])
def test_session_validation_names_the_line(tmp_path, text, match):
    with pytest.raises(InputError, match=match):
        read_session(_csv(tmp_path, text))


def test_session_round_trip_and_refuses_overwrite(tmp_path):
    s = paper_session(1, unload=True, repeats=2)
    p = write_session(s, tmp_path / "a.csv")
    r = read_session(p)
    assert np.allclose(r.reading, s.reading, rtol=1e-8) and np.array_equal(r.mass_g, s.mass_g)
    assert list(r.direction) == list(s.direction) and r.lever_arm_m == s.lever_arm_m
    assert r.reading_unit == "mV" and r.sensor_id == "paper-link1" and len(r.sha256) == 64
    with pytest.raises(InputError, match="exists"):
        write_session(s, p)


def test_shipped_sessions_are_the_simulator_output():
    from torquebench.io import REPO_ROOT
    for link in (1, 2):
        r = read_session(REPO_ROOT / "calibration" / "data" / f"paper_link{link}_session.csv")
        assert "SIMULATED" in r.meta["note"]
        assert np.allclose(r.reading, paper_session(link).reading, rtol=0, atol=1e-7)


# ---- closed form ---------------------------------------------------------------------------
def test_exact_posterior_against_textbook_formulas():
    rng = np.random.default_rng(0)
    x = np.repeat(np.linspace(0, 1000, 10), 3)
    y = 0.01 * x + 2 + rng.normal(0, 0.1, x.size)
    ex = exact_posterior(design_matrix(x, "linear"), y)
    b, a = np.polyfit(x, y, 1)[::-1][0], np.polyfit(x, y, 1)[0]
    assert np.allclose(ex.beta, [a, b])
    n = x.size
    sxx = np.sum((x - x.mean()) ** 2)
    s2 = np.sum((y - a * x - b) ** 2) / (n - 2)
    assert np.isclose(ex.std[0], np.sqrt(s2 / sxx * (n - 2) / (n - 4)))        # t_ν variance
    assert np.isclose(ex.r2, np.corrcoef(x, y)[0, 1] ** 2)
    # log σ moments against brute-force draws of the scaled-inverse-χ² posterior
    sig2 = (n - 2) * s2 / rng.chisquare(n - 2, 400_000)
    m, sd = ex.log_sigma_moments()
    assert abs(0.5 * np.log(sig2).mean() - m) < 1e-3 and abs(0.5 * np.log(sig2).std() - sd) < 1e-3
    assert abs(np.sqrt(sig2).mean() - ex.sigma_mean()) < 1e-3 * ex.sigma_mean()


def test_credible_intervals_cover_the_truth_at_their_level():
    """Simulator + exact posterior: the 68 % interval covers the true slope ≈ 68 % of the time."""
    spec = paper_spec(1)
    hits = []
    for seed in range(300):
        s = simulate_session(spec, np.random.default_rng(1000 + seed))
        ex = exact_posterior(design_matrix(s.mass_g, "linear"), s.reading)
        q = ex.quantiles()
        hits.append([(q[0, j] <= t <= q[2, j]) for j, t in
                     enumerate((spec.slope_mV_per_g, spec.offset_mV))])
    cover = np.mean(hits, axis=0)
    assert np.all(np.abs(cover - 0.6827) < 4 * np.sqrt(0.68 * 0.32 / 300)), cover


# ---- emcee ---------------------------------------------------------------------------------
def _mc_check(fit, k=4.0):
    n_eff = fit.samples.shape[0] / fit.autocorr_time[:-1]
    ex = fit.exact
    z_mean = (fit.mean[:-1] - ex.beta) / (ex.std / np.sqrt(n_eff))
    z_std = (fit.std[:-1] / ex.std - 1) / np.sqrt(1 / (2 * n_eff))
    assert np.all(np.abs(z_mean) < k), z_mean
    assert np.all(np.abs(z_std) < k), z_std
    ls_m, ls_s = ex.log_sigma_moments()
    n_eff_s = fit.samples.shape[0] / fit.autocorr_time[-1]
    assert abs(fit.samples[:, -1].mean() - ls_m) < k * ls_s / np.sqrt(n_eff_s)


def test_emcee_matches_exact_posterior_and_recovers_paper_fits():
    for link in (1, 2):
        s = paper_session(link)
        fit = fit_session(s, seed=link)
        assert fit.converged and fit.n_steps >= 50 * fit.tau_max
        assert fit.burn_in >= 2 * fit.tau_max
        assert 0.15 < fit.acceptance_fraction < 0.7
        _mc_check(fit)
        truth = np.array([PAPER_FITS[link]["slope_mV_per_g"], PAPER_FITS[link]["offset_mV"]])
        lo, hi = np.quantile(fit.samples[:, :2], [0.0015, 0.9985], axis=0)   # 99.7 % interval
        assert np.all((lo <= truth) & (truth <= hi)), (link, lo, hi, truth)
        assert abs(fit.exact.r2 - PAPER_FITS[link]["r2"]) < 3e-4 if link == 1 else 5e-5


def test_hysteresis_and_quadratic_models_match_exact():
    s = paper_session(1, unload=True, hysteresis_Nm=0.01, repeats=3)
    fit = fit_session(s, "hysteresis", seed=3)
    _mc_check(fit)
    # torque-equivalent hysteresis 0.01 N·m → reading offset 0.01 N·m · S (mV per N·m)
    S_mV_per_Nm = 0.0115 / (9.81e-3 * 0.205)
    assert abs(fit.mean[2] - 0.01 * S_mV_per_Nm) < 4 * fit.std[2]
    q = paper_session(2, quad_mV_per_g2=-2e-6)
    fq = fit_session(q, "quadratic", seed=4)
    _mc_check(fq)
    assert abs(fq.mean[2] + 2e-6) < 4 * fq.std[2]


def test_errors_in_load_term_separates_mass_uncertainty_from_reading_noise():
    spec = SessionSpec(repeat_noise_mV=0.02, repeats=5)
    s = simulate_session(spec, np.random.default_rng(5))
    sigma_m = 5.0                                   # g: each placed mass off by N(0, 5 g)
    s.reading = s.reading + spec.slope_mV_per_g * np.random.default_rng(6).normal(0, sigma_m, len(s))
    plain = fit_session(s, seed=1)
    eiv = fit_session(s, mass_std_g=sigma_m, seed=1)
    true_total = np.hypot(0.02, spec.slope_mV_per_g * sigma_m)
    assert abs(plain.sigma - true_total) < 0.25 * true_total
    assert eiv.sigma < 0.5 * plain.sigma
    assert abs(eiv.mean[0] - spec.slope_mV_per_g) < 4 * eiv.std[0]


def test_unconverged_fit_is_flagged_and_refused(tmp_path):
    from calibration.store import calibration_payload
    s = paper_session(1)
    fit = fit_session(s, max_steps=120, min_steps=100, seed=0)
    assert not fit.converged and "not converged" in fit.reason
    with pytest.raises(InputError, match="unconverged"):
        calibration_payload(fit, s)


def test_model_identifiability_errors():
    s = paper_session(1)                                        # no unloading readings
    with pytest.raises(InputError, match="hysteresis.*unload"):
        fit_session(s, "hysteresis")
    two = Session(mass_g=np.array([0.0, 0, 0, 100, 100, 100]), reading=np.arange(6.0),
                  direction=np.full(6, "load"), repeat=np.zeros(6, int), timestamp_s=np.zeros(6))
    with pytest.raises(InputError, match="at least 3 load levels"):
        fit_session(two, "quadratic")


# ---- characterization ----------------------------------------------------------------------
def test_characterization_recovers_injected_hysteresis_and_nonlinearity():
    from calibration.characterize import characterize
    spec = SessionSpec(unload=True, hysteresis_Nm=0.02, repeats=3, n_avg=4096)
    c = characterize(simulate_session(spec, np.random.default_rng(0)))
    fs_Nm = 1.0 * 9.81 * 0.205 * (1 - 0.01)                      # 10 g … 1000 g
    assert abs(c["hysteresis_pct_fs"] - 100 * 0.02 / fs_Nm) < 0.05
    spec = SessionSpec(quad_mV_per_g2=-1e-6, repeats=1, n_avg=4096)
    c = characterize(simulate_session(spec, np.random.default_rng(0)))
    # BFSL deviation of a parabola c m² on the level set, computed independently
    m = np.asarray(spec.masses_g)
    dev = -1e-6 * m**2 - np.polyval(np.polyfit(m, -1e-6 * m**2, 1), m)
    assert abs(c["nonlinearity_pct_fs"] - 100 * np.abs(dev).max() / c["fso"]) < 0.02
    assert np.isnan(c["hysteresis_pct_fs"]) and np.isnan(c["repeatability_pct_fs"])


# ---- fidelity (paper Fig. 3) ---------------------------------------------------------------
def test_motor_current_model_physics():
    from calibration.fidelity import MotorModel
    ideal = MotorModel(coulomb_Nm=0, viscous_Nm_s_per_rad=0, efficiency=1, rotor_inertia_kg_m2=0)
    tau = np.linspace(-2, 2, 9)
    assert np.allclose(ideal.estimate_Nm(ideal.current_A(tau, 0.3, 0.0)), tau)
    m = MotorModel(coulomb_Nm=0.0, viscous_Nm_s_per_rad=0.0, rotor_inertia_kg_m2=0)
    # lifting (τ ω > 0): the motor supplies the gearbox loss; lowering: the load back-drives it
    assert np.isclose(m.estimate_Nm(m.current_A(1.0, 0.5, 0)), 1 / 0.9)
    assert np.isclose(m.estimate_Nm(m.current_A(1.0, -0.5, 0)), 0.9)
    f = MotorModel(efficiency=1, rotor_inertia_kg_m2=0)
    assert np.isclose(f.estimate_Nm(f.current_A(0.0, 10.0, 0)), 0.15 + 0.03 * 10, rtol=1e-6)


def test_sensor_beats_motor_current_on_loading_trajectory():
    from calibration.fidelity import torque_fidelity
    r = torque_fidelity(seed=3)
    s, m = r["sensor"], r["motor_current"]
    assert s["r2"] > 0.999 and s["mae_Nm"] < 0.0286          # at least as good as the paper's
    assert m["r2"] < s["r2"] and m["mae_Nm"] > 5 * s["mae_Nm"]
    assert 0 < r["truth_Nm"].min() + 1e-9 and r["truth_Nm"].max() <= 2.0 + 1e-9


def test_session_with_missing_timestamps_and_bom_round_trips(tmp_path):
    p = tmp_path / "s.csv"
    p.write_text("\ufeffmass_g,reading,timestamp\n0,1.0,\n100,2.0,3.5\n")
    s = read_session(p)
    assert np.isnan(s.timestamp_s[0]) and s.timestamp_s[1] == 3.5
    r = read_session(write_session(s, tmp_path / "t.csv"))
    assert np.isnan(r.timestamp_s[0]) and r.timestamp_s[1] == 3.5


def test_mc_standard_error_and_rhat_are_honest():
    """The reported MC error of each posterior mean is the size of the actual deviation from the
    exact posterior mean, over independent seeds; split R̂ ≈ 1 once converged, > 1 for a stuck start."""
    s = paper_session(1)
    devs, ses = [], []
    for seed in range(8):
        fit = fit_session(s, seed=seed, n_walkers=32)
        p = len(fit.exact.beta)
        devs.append(fit.mean[:p] - fit.exact.beta)
        ses.append(fit.mc_standard_error[:p])
        assert fit.converged and fit.rhat < 1.05
    z = np.array(devs) / np.array(ses)
    assert 0.4 < np.sqrt(np.mean(z ** 2)) < 2.5          # z-scores of unit size (16 values)
    short = fit_session(s, max_steps=60, min_steps=60, seed=0, n_walkers=32)
    assert short.rhat > fit.rhat
