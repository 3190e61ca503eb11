"""Eq. 5 isolation on whitened rows (estimator.detection.whitened_thresholds, as the estimator's paper method runs it): thresholds from the
noise model's residual covariance at a stated per-row false-isolation probability."""

import numpy as np
import pytest
from scipy.stats import norm

from estimator import noise as Nz
from estimator.log import SensorLog
from estimator.estimate import estimate
from estimator.robot import paper_leg
from estimator.synthetic import inverse_dynamics_log

from test_noise_detection import NOISE, _noisy

ROBOT = paper_leg()
DT = 1e-3
SIGMA = np.r_[0.1, 0.1, 0.01, 0.005, 0.005]          # the paper leg's sensors


def _poked(link, T=6000, seed=3):
    t = np.arange(T) * DT
    q = np.tile([0.0, 0.0, 0.0, 0.9, -1.6], (T, 1))
    z = np.zeros_like(q)
    log, _ = inverse_dynamics_log(ROBOT, t, q, z, z, link, 0.5, [-1.5, 2.6], active=t >= 2.0)
    tau = log.tau_meas + np.random.default_rng(seed).standard_normal((T, 5)) * SIGMA
    return SensorLog(t=t, q=q, dq=z, tau_Nm=tau[:, 3:], wrench=tau[:, :3])


def test_link1_contact_is_isolated_to_link1_under_the_paper_leg_noise():
    est = estimate(ROBOT, _poked(1), method="paper")
    held = est.contact & (est.t > 2.1)
    assert held.sum() > 3500
    frac = (est.link[held] == 1).mean()
    R = Nz.residual_covariance(ROBOT, [0, 0, 0, 0.9, -1.6], np.zeros(5), Nz.paper_leg_noise(), 100.0, DT)[0]
    alpha = DT / 3600
    assert est.info["isolation_thresholds"] == pytest.approx(np.sqrt(np.diag(R)[3:]) * norm.isf(alpha / 2))
    assert "noise model" in est.info["isolation_thresholds_source"]
    print(f"link-1 poke: {100 * frac:.2f} % of contact samples isolated to link 1, thresholds "
          f"{est.info['isolation_thresholds']}")
    assert frac == 1.0                     # α = 2.8e-7 per sample: no false link-2 call expected
    est2 = estimate(ROBOT, _poked(2), method="paper")
    held2 = est2.contact & (est2.t > 2.1)
    assert (est2.link[held2] == 2).mean() == 1.0


@pytest.mark.parametrize("alpha", [1e-2, 1e-3])
def test_per_row_false_isolation_rate_matches_target(alpha):
    """Contact-free noise (velocity noise too), 300k samples: each joint row exceeds its threshold
    on a fraction α of the samples, within 5 sampling σ (n_eff from the correlation time)."""
    t, q, dq, dqm, tau = _noisy(300_000, 12)
    log = SensorLog(t=t, q=q, dq=dqm, tau_Nm=tau[:, 3:], wrench=tau[:, :3])
    est = estimate(ROBOT, log, method="paper", noise=NOISE, false_alarm_rate=(alpha, "sample"))
    th = np.asarray(est.info["isolation_thresholds"])
    above = np.abs(est.residual[200:, 3:]) > th
    a = np.exp(-100 * DT)
    se = np.sqrt(alpha / (above.shape[0] * (1 - a) / (1 + a)))
    print(f"α = {alpha:g}: per-row exceedance {above.mean(axis=0)} ± {se:.2g}")
    assert np.all(np.abs(above.mean(axis=0) - alpha) < 5 * se)


def test_quiet_window_keeps_the_robust_path():
    t, q, dq, dqm, tau = _noisy(20_000, 13)
    log = SensorLog(t=t, q=q, dq=dqm, tau_Nm=tau[:, 3:], wrench=tau[:, :3])
    est = estimate(ROBOT, log, method="paper", quiet_window=(1.0, 15.0))
    assert est.info["isolation_thresholds_source"].startswith("robust")
    from estimator.detection import robust_sigma

    r = est.residual[~est.contact, 3:]
    assert est.info["isolation_thresholds"] == pytest.approx(np.maximum(0.01, 5 * robust_sigma(r)))
