"""Our floating-base simulator against an independent one: the MuJoCo sample log (examples/leg_poke).

Same scene (Table I leg, I_base = 0.002, Table II base springs, PD K_P = 500, K_D = 10 at
q = (0.9, −1.6) from rest, 3 N on link 2 at α = 0.4, direction 2.0 rad, 0.4–0.9 s), no noise.
Measured with BDF (rtol 1e-6): |Δq| ≤ 1.1e-8 rad, |Δτ| ≤ 2.7e-6 N·m (of 0.83), |ΔW| ≤ 5.3e-5 N
(of 16.3 N); with Radau at rtol 1e-8 the wrench gap falls to 3e-6 N, so what remains is MuJoCo's
own RK4 (20 kHz) truncation. Tolerances are about 5× the measured gaps.
"""

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from estimator.robot import paper_leg
from estimator.sim import Controller, Poke, Sensors, SimConfig, simulate

SAMPLES = Path(__file__).resolve().parents[1] / "examples" / "leg_poke"


@pytest.fixture(scope="module")
def pair():
    ref = pd.read_csv(SAMPLES / "leg_poke.csv")
    truth = pd.read_csv(SAMPLES / "leg_poke.truth.csv")
    cfg = SimConfig(robot=paper_leg(), controller=Controller(q0_rad=np.array([0.9, -1.6])),
                    pokes=(Poke(2, 0.4, 3.0, 2.0, 0.4, 0.9),), duration_s=float(ref.t.iloc[-1]),
                    sensors=Sensors(torque_noise_Nm=0.0, ft_noise=np.zeros(3)))
    return ref, truth, simulate(cfg)


def test_same_sample_times(pair):
    ref, _, res = pair
    assert len(res.t) == len(ref) and np.allclose(res.t, ref.t.values, atol=1e-12)


def test_coordinates_match_mujoco(pair):
    ref, _, res = pair
    gap = np.abs(ref[["x", "z", "theta", "q1", "q2"]].values - res.q).max()
    span = np.abs(ref[["x", "z", "theta", "q1", "q2"]].values - ref[["x", "z", "theta", "q1", "q2"]].values[0]).max()
    assert span > 1e-3          # the leg does move (sag + poke)
    assert gap < 5e-8
    assert np.abs(ref[["dx", "dz", "dtheta", "dq1", "dq2"]].values - res.dq).max() < 2e-6


def test_torques_and_base_wrench_match_mujoco(pair):
    ref, _, res = pair
    assert np.abs(ref[["tau1", "tau2"]].values - res.tau_Nm).max() < 1.5e-5
    assert np.abs(ref[["Fx", "Fz", "My"]].values - res.wrench).max() < 3e-4
    # and the measured log equals the truth when the noise is off
    assert np.array_equal(res.log.tau_Nm, res.tau_Nm)


def test_truth_file_matches_sample_truth(pair):
    _, truth, res = pair
    assert np.array_equal(truth.link.values, res.truth["link"])
    on = truth.link.values > 0
    for c in ("alpha", "Fx", "Fz"):
        assert np.allclose(truth[c].values[on], res.truth[c][on], atol=1e-9)
    assert np.allclose(truth[["px", "pz"]].values[on], np.column_stack([res.truth["px"], res.truth["pz"]])[on],
                       atol=1e-7)
