"""The identification's excitation: the shipped Fourier scene stays in its joint ranges and is
better conditioned than the single sines of moving_leg; the design improves on its start;
multi-harmonic controller fields are validated."""

import re
import numpy as np
import pytest

from estimator import excitation as X
from estimator.model import ModelUncertainty
from estimator.noise import paper_leg_noise
from estimator.robot import paper_leg
from userio.errors import InputError
from torquebench.scenes import load_scene, scene_path

ROBOT = paper_leg()
PRIOR = ROBOT.parameter_covariance(ModelUncertainty.uniform(0.3))


def _cond(ctrl, duration=4.0, rank=None):
    info = X.information(ROBOT, X.Fourier.from_controller(ctrl), duration, paper_leg_noise(), PRIOR)
    rank = rank or X.structural_rank(info)
    return X.condition_number(info, rank), rank


def test_shipped_excitation_scene_is_in_range_and_well_conditioned():
    scene = load_scene(scene_path("identification_excitation"))
    ctrl = scene.sim.controller
    assert ctrl.harmonics()[0].shape == (2, 3) and scene.sim.duration_s == 20.0
    assert not scene.sim.pokes
    q, dq, _ = X.Fourier.from_controller(ctrl).evaluate(np.linspace(0, 4.0, 4001))
    assert np.all(q >= [-0.6, -2.2]) and np.all(q <= [1.2, -0.3])
    assert np.abs(dq).max() <= 6.0
    cond, rank = _cond(ctrl)
    single, _ = _cond(load_scene(scene_path("moving_leg")).sim.controller, rank=rank)
    print(f"condition number: excitation {cond:.3g}, moving_leg's single sines {single:.3g} (rank {rank})")
    assert rank == 7 and cond < 0.75 * single


def test_design_improves_on_its_start():
    start = X._start(np.array([0.3, -1.25]), np.array([0.9, 0.95]), 3, 0.25, 1)
    info = X.information(ROBOT, start, 4.0, paper_leg_noise(), PRIOR)
    c0 = X.condition_number(info, X.structural_rank(info))
    tr, c = X.design(ROBOT, [-0.6, -2.2], [1.2, -0.3], harmonics=3, base_Hz=0.25, duration_s=4.0,
                     seed=1, iterations=60, max_rate_rad_per_s=6.0)
    q, dq, _ = tr.evaluate(np.linspace(0, 4.0, 801))
    assert c < c0
    assert np.all(q >= np.array([-0.6, -2.2]) - 0.02) and np.all(q <= np.array([1.2, -0.3]) + 0.02)


@pytest.mark.parametrize("field, value, message", [
    ("amplitude_rad", "[[0.1, 0.2], [0.1]]", "every joint needs the same number of harmonics"),
    ("frequency_Hz", "[0.25, 0.25]", "expected the shape of amplitude_rad [2, 2], got [2]"),
    ("amplitude_rad", "[[0.1, 0.2]]", "expected 2 values (one per joint), got 1"),
])
def test_bad_harmonics_are_named(tmp_path, field, value, message):
    text = scene_path("identification_excitation").read_text()
    good = {"amplitude_rad": "[[0.1, 0.2], [0.1, 0.2]]", "frequency_Hz": "[[0.25, 0.5], [0.25, 0.5]]",
            "phase_rad": "[[0.0, 0.0], [0.0, 0.0]]"}
    good[field] = value
    start, end = text.index("amplitude_rad"), text.index("kp =")
    body = "\n".join(f"{k} = {v}" for k, v in good.items()) + "\n"
    p = tmp_path / "s.toml"
    p.write_text(text[:start] + body + text[end:])
    with pytest.raises(InputError, match=f"controller.{field}: .*{re.escape(message)}"):
        load_scene(p)
