"""A URDF robot's 3-D log is checked against the robot's dynamics before estimation, as a planar
log is (estimator.plausibility.check_head_model through the RobotModel interface): a group of
channels in the wrong unit or with its sign flipped is refused naming it; a clean log passes."""

import dataclasses

import numpy as np
import pytest

from userio.errors import InputError
from estimator.plausibility import check_head_model
from torquebench.io import REPO_ROOT

LOG = REPO_ROOT / "examples" / "spatial" / "leg_pokes.csv"


@pytest.fixture(scope="module")
def leg():
    from estimator.spatial.logs import read_noise, read_spatial_log
    from estimator.spatial.model import UrdfModel
    from estimator.spatial.robot import load_spatial_robot

    robot = load_spatial_robot(REPO_ROOT / "robots" / "quadruped_leg.toml")
    model = UrdfModel(robot)
    return model, read_spatial_log(LOG, robot, model), read_noise(LOG, robot)


def test_the_shipped_log_passes(leg):
    model, log, noise = leg
    assert check_head_model(model, log, noise) == []


@pytest.mark.parametrize("edit, needle", [
    (lambda lg: dataclasses.replace(lg, tau_Nm=lg.tau_Nm * 1000), r"joint torques are 1e\+03"),
    (lambda lg: dataclasses.replace(lg, wrench=lg.wrench * np.r_[-1, -1, -1, 1, 1, 1]), "forces are -1"),
    (lambda lg: dataclasses.replace(lg, wrench=0 * lg.wrench, tau_Nm=0 * lg.tau_Nm), "exactly 0"),
])
def test_unit_and_sign_mixups_are_refused(leg, edit, needle):
    model, log, noise = leg
    with pytest.raises(InputError, match=needle):
        check_head_model(model, edit(log), noise)


def test_moments_in_the_wrong_unit_are_at_least_warned_about(leg):
    """The base moment rows hold p × f beside the sensor's moment, so a moment unit error is not a
    clean factor on them: a warning naming a moment row (not a refusal) is what can be said."""
    model, log, noise = leg
    bad = dataclasses.replace(log, wrench=log.wrench * np.r_[1, 1, 1, 1e-3, 1e-3, 1e-3])
    try:
        found = check_head_model(model, bad, noise)
    except InputError as exc:
        found = [str(exc)]
    assert found and any(m in found[0] for m in ("M_x", "M_y", "M_z", "moments"))
