"""The independent MuJoCo log examples/leg_poke/leg_poke.csv: a 3 N poke on link 2 at α = 0.4,
direction 2.0 rad, from t = 0.4 s to 0.9 s, on the paper leg held by its servos.

Tolerances from physics: the log is noise-free, sampled at 1 kHz with a step on and off. In the
window t ∈ [0.5, 0.9) the observer's step transient is 3 N · exp(−K · 0.1 s) = 1.4e-4 N at
K = 100 s⁻¹; the base rings on its springs (ω ≈ 65 rad/s, amplitude ≈ F/K_b = 0.6 mm), so the
trapezoid rule for ∫u over a 1 ms step leaves ≈ Δt²/12 · m ω³ x ≈ 2e-5 N. We allow 2e-3 N on F,
1e-3 on α and 0.5 mm on the point (≈ 10× that budget, for MuJoCo's own integration error).
"""

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from estimator import dynamics as D
from estimator.localization import bias_forces
from estimator.log_reader import read_log
from estimator.estimate import estimate
from estimator.robot import paper_leg

SAMPLES = Path(__file__).resolve().parents[1] / "examples" / "leg_poke"
LOG = SAMPLES / "leg_poke.csv"
F_TRUE = 3.0 * np.array([np.cos(2.0), np.sin(2.0)])


@pytest.fixture(scope="module")
def data():
    robot = paper_leg()
    return robot, read_log(LOG, robot), pd.read_csv(SAMPLES / "leg_poke.truth.csv")


def test_static_balance_gives_the_poke(data):
    """Independent of the observer: in the held posture G − τ_meas = Jᵀ F (forces ON the robot)."""
    robot, log, _ = data
    k = np.searchsorted(log.t, 0.899)          # the base ringing has decayed (e^{-21 t})
    lhs = bias_forces(robot, log.q[k], log.dq[k])[0] - log.tau_meas[k]
    rhs = D.point_jacobian(robot, log.q[k], 2, 0.4).T @ F_TRUE
    assert np.abs(lhs - rhs).max() < 1e-4      # M q̈ of the residual ringing is ignored here


@pytest.mark.parametrize("method", ["dynamic", "paper"])
def test_recovers_the_poke(data, method):
    robot, log, truth = data
    est = estimate(robot, log, method=method)
    on = (log.t >= 0.5) & (log.t < 0.9)
    assert not est.contact[log.t < 0.4].any()
    assert est.contact[(log.t > 0.4015) & (log.t < 0.9)].all()
    assert not est.contact[log.t > 1.0].any()
    assert np.all(est.link[on] == 2)
    alpha_err = np.abs(est.alpha[on] - 0.4).max()
    F_err = np.hypot(est.Fx[on] - F_TRUE[0], est.Fz[on] - F_TRUE[1]).max()
    p_err = np.hypot(est.px[on] - truth.px[on], est.pz[on] - truth.pz[on]).max()
    print(f"leg_poke {method}: |α − 0.4| ≤ {alpha_err:.2e}, |F − F_true| ≤ {F_err:.2e} N, "
          f"|p − p_true| ≤ {1e3 * p_err:.3f} mm")
    if method == "dynamic":
        assert alpha_err < 1e-3 and F_err < 2e-3 and p_err < 5e-4
    else:
        # quasi-static: the servo-held leg is nearly at rest, but M q̈ of the ringing base is
        # read as force; still on the right link and within the paper's centimetre class
        assert np.nanmedian(np.abs(est.alpha[on] - 0.4)) < 0.01
        assert np.nanmedian(np.hypot(est.px[on] - truth.px[on], est.pz[on] - truth.pz[on])) < 0.005
    intervals = est.intervals()
    assert len(intervals) == 1 and intervals[0]["link"] == 2
    assert abs(intervals[0]["t_start_s"] - 0.401) < 2e-3
