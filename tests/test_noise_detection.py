"""Residual noise from the sensor noise model (closed-form Lyapunov) against Monte Carlo, and the
chi-square detector's false-alarm rate against its target."""

import numpy as np
import pytest

from estimator import noise as Nz
from estimator import observer as O
from userio.errors import InputError
from estimator.robot import paper_leg
from estimator.synthetic import inverse_dynamics_log, sinusoidal_motion

ROBOT = paper_leg()
DT = 1e-3
NOISE = Nz.NoiseModel(torque_sigma_Nm=[0.005], ft_sigma=[0.1, 0.1, 0.01],
                      velocity_sigma_rad_per_s=0.002)


def _noisy(T, seed, moving=False, noise=NOISE, mean_timing=False):
    t = np.arange(T) * DT
    if moving:
        q, dq, ddq = sinusoidal_motion(ROBOT, t, frequency_Hz=0.5, base_amplitude=(0.01, 0.01, 0.05))
    else:
        q = np.tile([0.0, 0.0, 0.0, 0.9, -1.6], (T, 1))
        dq = ddq = np.zeros_like(q)
    log, _ = inverse_dynamics_log(ROBOT, t, q, dq, ddq, 2, 0.5, np.zeros(2))
    rng = np.random.default_rng(seed)
    sig = np.r_[noise.ft_sigma, np.broadcast_to(noise.torque_sigma_Nm, (2,))]
    tau = log.tau_meas + rng.standard_normal((T, 5)) * sig
    dqm = dq.copy()
    dqm[:, 3:] += rng.standard_normal((T, 2)) * noise.velocity_sigma_rad_per_s
    return t, q, dq, dqm, tau


def test_covariance_matches_monte_carlo():
    t, q, dq, dqm, tau = _noisy(400_000, 1)
    r = O.residual_offline(ROBOT, t, q, dqm, tau, 100.0)[1000:]
    emp = np.cov(r, rowvar=False)
    pred = Nz.residual_covariance(ROBOT, q[0], dq[0], NOISE, 100.0, DT)[0]
    rel = np.abs(np.sqrt(np.diag(emp)) / np.sqrt(np.diag(pred)) - 1)
    print("σ_r predicted", np.sqrt(np.diag(pred)), "relative error", rel)
    # 400k samples, correlation time ~20 samples: ~20k independent values → σ error ≲ 1 %
    assert rel.max() < 0.03
    corr_e = emp / np.sqrt(np.outer(np.diag(emp), np.diag(emp)))
    corr_p = pred / np.sqrt(np.outer(np.diag(pred), np.diag(pred)))
    assert np.abs(corr_e - corr_p).max() < 0.05
    # without velocity noise: the closed form is the filter factor √((1−a)/2) · σ on each row
    only_tau = Nz.NoiseModel(torque_sigma_Nm=[0.005], ft_sigma=[0.1, 0.1, 0.01])
    R = Nz.residual_covariance(ROBOT, q[0], dq[0], only_tau, 100.0, DT)[0]
    a = np.exp(-100 * DT)
    f = np.sqrt((1 - a) / 2)
    assert np.allclose(np.sqrt(np.diag(R)), f * np.r_[0.1, 0.1, 0.01, 0.005, 0.005], rtol=1e-9)


@pytest.mark.parametrize("alpha", [1e-2, 1e-3])
def test_false_alarm_fraction_matches_target(alpha):
    """Moving leg, contact-free, 300k samples: flagged fraction = α within 5 sampling σ (the
    sampling σ inflated by the residual's correlation time)."""
    t, q, dq, dqm, tau = _noisy(300_000, 2, moving=True)
    r = O.residual_offline(ROBOT, t, q, dqm, tau, 100.0)
    stride = 10
    R = Nz.residual_covariance(ROBOT, q[::stride], dq[::stride], NOISE, 100.0, DT)
    s = Nz.whitened_statistic(r, R, stride)[200:]
    flagged = s > Nz.chi2_threshold(alpha, 5)
    a = np.exp(-100 * DT)
    n_eff = len(s) / ((1 + a) / (1 - a))
    se = np.sqrt(alpha * (1 - alpha) / n_eff)
    print(f"α = {alpha:g}: flagged {flagged.mean():.3g} ± {se:.2g}")
    assert abs(flagged.mean() - alpha) < 5 * se


def test_bad_noise_and_rates_are_input_errors():
    with pytest.raises(InputError, match="torque sigma"):
        Nz.NoiseModel(torque_sigma_Nm=[0.0], ft_sigma=[0.1, 0.1, 0.01])
    with pytest.raises(InputError, match="FT sigma"):
        Nz.NoiseModel(torque_sigma_Nm=[0.01], ft_sigma=[0.1, -0.1, 0.01])
    with pytest.raises(InputError, match="false-alarm"):
        Nz.per_sample_rate(2.0, "sample", DT)
    with pytest.raises(InputError, match="false-alarm"):
        Nz.per_sample_rate(1000.0, "s", DT)
    assert Nz.per_sample_rate(1.0, "h", DT) == pytest.approx(DT / 3600)


def test_quiet_window_refuses_a_contact():
    t, q, dq, dqm, tau = _noisy(20_000, 3)
    r = O.residual_offline(ROBOT, t, q, dqm, tau, 100.0)
    C = Nz.quiet_covariance(r, t, 1.0, 15.0, 100.0, DT)
    pred = Nz.residual_covariance(ROBOT, q[0], dq[0], NOISE, 100.0, DT)[0]
    assert np.allclose(np.sqrt(np.diag(C)), np.sqrt(np.diag(pred)), rtol=0.1)
    r2 = r.copy()
    r2[t > 10.0, 4] += 0.5 * (1 - np.exp(-100 * (t[t > 10.0] - 10.0)))    # a 0.5 N·m contact
    with pytest.raises(InputError, match="--quiet-window.*contains a contact"):
        Nz.quiet_covariance(r2, t, 1.0, 15.0, 100.0, DT)


def test_episode_error_estimate_matches_the_spread_of_answers():
    """A held 3 N poke under the issue's noise: the per-sample bound of α (the whitened fit
    reaches it) and the predicted per-sample 1σ of F agree with the standard deviation of the
    per-sample answers over the episode (within 15 %); the episode's own α is within 4 of its
    (much smaller) 1σ of the truth."""
    from estimator.log import SensorLog
    from estimator.estimate import estimate

    T = 60_000
    t = np.arange(T) * DT
    q = np.tile([0.0, 0.0, 0.0, 0.9, -1.6], (T, 1))
    z = np.zeros_like(q)
    log, _ = inverse_dynamics_log(ROBOT, t, q, z, z, 2, 0.4, [-1.5, 2.6], active=t >= 1.0)
    sig = np.r_[0.1, 0.1, 0.01, 0.005, 0.005]
    tau = log.tau_meas + np.random.default_rng(5).standard_normal((T, 5)) * sig
    noisy = SensorLog(t=t, q=q, dq=z, tau_Nm=tau[:, 3:], wrench=tau[:, :3])
    est = estimate(ROBOT, noisy)
    iv = max(est.intervals(), key=lambda i: i["samples"])
    steady = est.t > 1.2
    assert iv["alpha_bound_per_sample"] == pytest.approx(np.nanstd(est.alpha[steady]), rel=0.15)
    assert abs(iv["alpha"] - 0.4) < 4 * iv["alpha_error_estimate"]
    assert iv["alpha_error_estimate"] < 0.05 * iv["alpha_bound_per_sample"]
    for key, arr in (("Fx_N", est.Fx), ("Fz_N", est.Fz)):
        spread = np.nanstd(arr[steady])
        print(key, "predicted", iv[f"{key}_error_estimate"], "measured", spread)
        assert iv[f"{key}_error_per_sample"] == pytest.approx(spread, rel=0.15)
        assert "1σ" in iv[f"{key}_error_method"]
        assert iv[f"{key}_error_estimate"] < 0.1 * spread          # the mean's 1σ (intervals.SteadyForce)
        assert abs(iv[key] - {"Fx_N": -1.5, "Fz_N": 2.6}[key]) < 4 * iv[f"{key}_error_estimate"]
