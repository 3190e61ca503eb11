"""The detector's model-error term (estimator.model_error): Φ is the residual's exact sensitivity
to the file's parameters; the compiled loop equals the numpy form across chunks and gaps; with a
declared uncertainty (or an identification) the stated false-alarm rate holds on robots drawn
from it, held and moving; --quiet-window reads the sensor noise, not the model error, and
refuses a stretch its stated uncertainty does not explain; CLI options in one line."""

import json
from pathlib import Path

import numpy as np
import pytest

from estimator import compiled, inertial, observer
from userio.errors import InputError
from estimator.log import SensorLog
from estimator.model import ModelUncertainty
from estimator.model_error import ModelTerm, statistic_numpy
from estimator.noise import NoiseModel, quiet_covariance, residual_covariance
from estimator.estimate import estimate
from estimator.robot import paper_leg
from estimator.synthetic import inverse_dynamics_log, sinusoidal_motion

ROOT = Path(__file__).resolve().parents[1]
NOMINAL = paper_leg()
DECLARED = ModelUncertainty(mass_rel=0.05, inertia_rel=0.10, com_m=0.003)
NOISE = NoiseModel([0.005], [0.1, 0.1, 0.01])
SIG = np.r_[0.1, 0.1, 0.01, 0.005, 0.005]


def log_of(robot, moving=True, T=6000, seed=0, freq=1.0):
    t = np.arange(T) * 1e-3
    if moving:
        q, dq, ddq = sinusoidal_motion(robot, t, frequency_Hz=freq, base_amplitude=(0.002, 0.002, 0.01))
    else:
        q, dq, ddq = sinusoidal_motion(robot, t, amplitude_rad=(0.0, 0.0))
    log, _ = inverse_dynamics_log(robot, t, q, dq, ddq, 1, 0.5, [0, 0], active=np.zeros(T, bool))
    e = np.random.default_rng(seed).standard_normal((T, 5)) * SIG
    return SensorLog(t=t, q=q, dq=dq, tau_Nm=log.tau_Nm + e[:, 3:], wrench=log.wrench + e[:, :3])


def test_phi_is_the_residuals_exact_sensitivity_to_the_parameters():
    """The observer is linear in θ: r(θ_a) − r(θ_b) = Φ (θ_a − θ_b) on any log (here with a gap)."""
    log = log_of(inertial.perturbed(NOMINAL, DECLARED, 1), T=3000)
    t = log.t.copy()
    t[1500:] += 0.004                                         # skipped rows: a longer step
    other = inertial.perturbed(NOMINAL, DECLARED, 2)
    ra = observer.residual_offline(NOMINAL, t, log.q, log.dq, log.tau_meas, 100.0)
    rb = observer.residual_offline(other, t, log.q, log.dq, log.tau_meas, 100.0)
    term = ModelTerm(NOMINAL, np.eye(10), 100.0, 1e-3)          # S = I: G = Φ
    _, phi = term.statistic(t, log.q, log.dq, ra.T, np.eye(5)[None], np.zeros(len(t), np.int64))
    pred = np.einsum("tnk,k->tn", phi, NOMINAL.parameters() - other.parameters())
    assert np.abs(ra - rb).max() > 1e-3                       # a real difference
    np.testing.assert_allclose(ra - rb, pred, atol=1e-12 * 1e3 + 1e-9)


def test_compiled_term_equals_the_numpy_form_in_any_chunks():
    log = log_of(NOMINAL, T=2500)
    t = log.t.copy()
    t[1200:] += 0.003
    cov = NOMINAL.parameter_covariance(DECLARED)
    r = observer.residual_offline(NOMINAL, t, log.q, log.dq, log.tau_meas, 100.0).T
    Rn = residual_covariance(NOMINAL, log.q[:1], log.dq[:1], NOISE, 100.0, 1e-3)
    blk = np.zeros(len(t), np.int64)
    a = ModelTerm(NOMINAL, cov, 100.0, 1e-3)
    parts = [a.statistic(t[s], log.q[s], log.dq[s], r[:, s], Rn, blk[s])
             for s in (slice(0, 700), slice(700, 1900), slice(1900, None))]
    s1, G1 = np.concatenate([p[0] for p in parts]), np.concatenate([p[1] for p in parts])
    compiled.ENABLED = False
    try:
        s2, G2 = ModelTerm(NOMINAL, cov, 100.0, 1e-3).statistic(t, log.q, log.dq, r, Rn, blk)
    finally:
        compiled.ENABLED = True
    np.testing.assert_allclose(G1, G2, rtol=1e-9, atol=1e-15)
    np.testing.assert_allclose(s1, s2, rtol=1e-8)
    np.testing.assert_allclose(s2, statistic_numpy(r, G2, Rn, blk), rtol=1e-10)


@pytest.mark.parametrize("moving", [False, True], ids=["held", "moving"])
def test_declared_uncertainty_keeps_the_stated_rate_on_robots_drawn_from_it(moving):
    """Robots drawn from the declared uncertainty, logs with the declared noise: without the term
    nearly every sample flags; with it, the flagged fraction stays below 0.1 % on every robot."""
    flagged, bare = [], []
    for seed in range(8):
        true = inertial.perturbed(NOMINAL, DECLARED, 100 + seed)
        log = log_of(true, moving, seed=seed)
        flagged.append(estimate(NOMINAL, log, noise=NOISE, model_uncertainty=DECLARED).contact.mean())
        if seed < 2:
            bare.append(estimate(NOMINAL, log, noise=NOISE).contact.mean())
    print(f"{'moving' if moving else 'held'}: flagged {np.round(flagged, 5)}, without the term {bare}")
    assert max(flagged) < 1e-3
    assert min(bare) > 0.3


def test_the_statistic_is_chi_square_over_robot_draws():
    """Over robots drawn from Σ_θ, s_k = r_kᵀ R_k⁻¹ r_k at one sample is χ²_n: its mean is n and
    its 99th percentile χ²_5's (the marginal law the stated rate rests on)."""
    from scipy.stats import chi2

    cov = NOMINAL.parameter_covariance(DECLARED)
    base = log_of(NOMINAL, T=1200, seed=0)
    t, q, dq = base.t, base.q, base.dq
    term_cov = ModelTerm(NOMINAL, cov, 100.0, 1e-3)
    Rn = residual_covariance(NOMINAL, q[:1], dq[:1], NOISE, 100.0, 1e-3)
    r_nom = observer.residual_offline(NOMINAL, t, q, dq, base.tau_meas, 100.0)
    term = ModelTerm(NOMINAL, np.eye(10), 100.0, 1e-3)
    _, phi = term.statistic(t, q, dq, r_nom.T, np.eye(5)[None], np.zeros(len(t), np.int64))
    rng = np.random.default_rng(3)
    S = np.linalg.cholesky(cov)
    k = 1100                                              # one moving sample
    _, G = term_cov.statistic(t, q, dq, r_nom.T, Rn, np.zeros(len(t), np.int64))
    R = Rn[0] + G[k] @ G[k].T
    Ln = np.linalg.cholesky(Rn[0])
    draws = phi[k] @ (S @ rng.standard_normal((10, 20000))) + Ln @ rng.standard_normal((5, 20000))
    s = np.einsum("in,ij,jn->n", draws, np.linalg.inv(R), draws)
    assert abs(s.mean() - 5) < 0.1
    assert abs(np.quantile(s, 0.99) - chi2.ppf(0.99, 5)) < 0.6


def test_quiet_window_reads_the_noise_not_the_model_error():
    """On a moving leg with a 3 % model error the spread of r is several times the noise's; the
    innovations give the noise covariance within a few per cent."""
    true = inertial.perturbed(NOMINAL, ModelUncertainty.uniform(0.03), 2)
    log = log_of(true, T=16000)
    Rth = residual_covariance(NOMINAL, log.q[:1], log.dq[:1], NOISE, 100.0, 1e-3)[0]
    r = observer.residual_offline(NOMINAL, log.t, log.q, log.dq, log.tau_meas, 100.0)
    R = quiet_covariance(r, log.t, 1.0, 15.0, 100.0, 1e-3)
    ratio = np.sqrt(np.diag(R) / np.diag(Rth))
    spread = np.std(r[1000:15000], axis=0) / np.sqrt(np.diag(Rth))
    print("noise read / true:", np.round(ratio, 3), "spread of r / noise:", np.round(spread, 2))
    assert np.all(np.abs(ratio - 1) < 0.05) and spread.max() > 2


def test_quiet_window_on_a_moving_log_needs_the_model_uncertainty():
    true = inertial.perturbed(NOMINAL, ModelUncertainty.uniform(0.03), 2)
    log = log_of(true, T=8000)
    with pytest.raises(InputError, match="--quiet-window: the residual over 1–7 s is .* what its "
                                         "sensor noise explains: .*or model error"):
        estimate(NOMINAL, log, quiet_window=(1.0, 7.0))
    with pytest.raises(InputError, match=r"the model uncertainty \(option: masses ±0.3 %.*does not cover"):
        estimate(NOMINAL, log, quiet_window=(1.0, 7.0),
                 model_uncertainty=ModelUncertainty.uniform(0.003))
    est = estimate(NOMINAL, log, quiet_window=(1.0, 7.0),
                   model_uncertainty=ModelUncertainty.uniform(0.03))
    assert est.contact.mean() < 1e-3
    assert "innovations" in est.info["residual_noise_source"]
    exact = estimate(true, log, quiet_window=(1.0, 7.0))        # the exact model: noise only
    assert exact.contact.mean() < 1e-3


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


def test_estimate_option_and_its_errors():
    log = ROOT / "examples" / "sim" / "paper_floating_link1.csv"
    proc = _tb("estimate", log, "--model-uncertainty", "0.05", "--json")
    assert proc.returncode == 0, proc.stderr
    out = json.loads(proc.stdout)
    assert out["model_uncertainty_source"].startswith("option: masses ±5 %")
    assert len(out["residual_model_sigma"]) == 5 and out["intervals"]
    plain = json.loads(_tb("estimate", log, "--json").stdout)
    # the interval's error estimate grows with the model uncertainty
    assert out["intervals"][0]["px_m_error_estimate"] > 3 * plain["intervals"][0]["px_m_error_estimate"]
    for bad, msg in (("abc", "--model-uncertainty"), ("2", "--model-uncertainty: expected a relative")):
        p = _tb("estimate", log, "--model-uncertainty", bad)
        assert p.returncode == 2 and msg in p.stderr and len(p.stderr.strip().splitlines()) == 1
    p = _tb("estimate", log, "--model-uncertainty", "0.05", "--method", "paper")
    assert p.returncode == 2 and "dynamic method" in p.stderr
    p = _tb("estimate", log, "--model-uncertainty", "0.05", "--detector", "cusum")
    assert p.returncode == 2 and "use the chi2 detector" in p.stderr
