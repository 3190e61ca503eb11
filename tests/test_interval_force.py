"""An interval's mean force (estimator.intervals.SteadyForce): the observer's rise is left out and
corrected, so a held step force is read without the bias of the rise (the plain mean of a 150 ms
contact read 5–7 % low), and the stated 1σ of the mean covers the true force at its rate."""

import numpy as np
import pytest
from scipy.stats import binom

from estimator.estimate import estimate
from test_episode import NOISE, ROBOT, _held_log

CASES = [((0.3, -1.0), 2, 0.6, np.array([3.0, -4.0])), ((-0.5, -1.5), 1, 0.5, np.array([-2.0, -3.0]))]


def _interval(qj, link, alpha, F, seed, duration_s=0.15):
    log, _ = _held_log(qj, link, alpha, F, t_on=0.2, t_off=0.2 + duration_s,
                       T=int(round((0.5 + duration_s) * 1000)), seed=seed)
    est = estimate(ROBOT.with_base(False), log, noise=NOISE)
    return max(est.intervals(), key=lambda i: i["samples"])


@pytest.mark.parametrize("qj, link, alpha, F", CASES)
def test_held_step_force_mean_has_no_rise_bias(qj, link, alpha, F):
    """Averaged over 6 seeds the interval's mean force is within 3σ of the mean's spread of the
    truth; the rise alone (Σ a^j ≈ 10.5 samples of a 150-sample contact) would put it 5–7 % low,
    i.e. ≥ 0.15 N on these 3.6–5 N forces: more than 20 of those σ."""
    rows = [_interval(qj, link, alpha, F, seed) for seed in range(6)]
    est = np.array([[r["Fx_N"], r["Fz_N"]] for r in rows])
    sd = np.array([[r["Fx_N_error_estimate"], r["Fz_N_error_estimate"]] for r in rows])
    err = est.mean(axis=0) - F
    assert np.all(np.abs(err) < 3 * sd.mean(axis=0) / np.sqrt(len(rows))), (err, sd.mean(axis=0))
    assert "rise" in rows[0]["Fx_N_error_method"]


@pytest.mark.slow
def test_stated_sigma_of_the_mean_force_covers_at_its_rate():
    """Monte Carlo over 2 cases × 40 seeds (160 force components): |F̄ − F| < 1σ and < 2σ at the
    nominal 68.3 % and 95.4 % (central 99 % binomial interval). Measured: 0.78 and 0.97 on 150 ms
    contacts, 0.67 and 0.98 on 500 ms ones (60 and 30 components)."""
    z = []
    for qj, link, alpha, F in CASES:
        for seed in range(40):
            r = _interval(qj, link, alpha, F, seed)
            z += [(r["Fx_N"] - F[0]) / r["Fx_N_error_estimate"], (r["Fz_N"] - F[1]) / r["Fz_N_error_estimate"]]
    z = np.abs(np.array(z))
    n = z.size
    for k, p in ((1, 0.6827), (2, 0.9545)):
        hits = int(np.sum(z < k))
        assert binom.ppf(0.005, n, p) <= hits <= binom.ppf(0.995, n, p), (k, hits, n)
