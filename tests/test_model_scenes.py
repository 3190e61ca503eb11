"""Scenes that simulate a robot other than the file their estimator reads ([robot] true_parameters
or a seeded perturbation): loading, validation in one line, the stage keys, and a short run whose
prediction carries the file's declared uncertainty."""

import re

import numpy as np
import pytest

from estimator.inertial import robot_toml
from estimator.model import ModelUncertainty
from estimator.robot import paper_leg
from torquebench import pipeline as P
from userio.errors import InputError
from torquebench.scenes import load_scene, scene_path

BASE = scene_path("paper_floating_link1").read_text()


def scene(tmp_path, table: str, name="s.toml", base=BASE):
    text = base.replace('robot = "paper_leg.toml"\n', "")
    p = tmp_path / name
    p.write_text(text + "\n[robot]\n" + table + "\n")
    return p


def test_a_perturbed_robot_is_simulated_and_the_file_is_estimated(tmp_path):
    s = load_scene(scene(tmp_path, 'file = "paper_leg.toml"\nperturbation = 0.05\nperturbation_seed = 4'))
    assert s.robot.name == "paper_leg" and s.sim.robot.name == "paper_leg_perturbed_4"
    assert not np.allclose(s.sim.robot.parameters(), s.robot.parameters())
    np.testing.assert_array_equal(s.sim.robot.lengths_m, s.robot.lengths_m)
    same = load_scene(scene(tmp_path, 'perturbation = 0.05\nperturbation_seed = 4', "b.toml"))
    np.testing.assert_array_equal(same.sim.robot.parameters(), s.sim.robot.parameters())
    zero = load_scene(scene(tmp_path, "perturbation = 0.0", "c.toml"))
    np.testing.assert_array_equal(zero.sim.robot.parameters(), zero.robot.parameters())
    keys = {str(p): {st.stage.name: st.key for st in P.plan(load_scene(p), ["estimates"])}
            for p in (tmp_path / "s.toml", tmp_path / "c.toml")}
    a, b = keys.values()
    assert a["simulation"] != b["simulation"]           # another robot is simulated


def test_true_parameters_from_a_file(tmp_path):
    true = paper_leg()
    from dataclasses import replace

    true = replace(true, masses_kg=true.masses_kg * 1.05, com_perp_m=np.array([0.003, -0.002]),
                   name="cad")
    (tmp_path / "cad.toml").write_text(robot_toml(true))
    s = load_scene(scene(tmp_path, 'true_parameters = "cad.toml"'))
    np.testing.assert_allclose(s.sim.robot.com_perp_m, [0.003, -0.002])
    assert s.robot.name == "paper_leg"
    (tmp_path / "long.toml").write_text(robot_toml(replace(true, lengths_m=true.lengths_m * 1.1)))
    with pytest.raises(InputError, match="robot.true_parameters: .*only inertial data may differ"):
        load_scene(scene(tmp_path, 'true_parameters = "long.toml"', "d.toml"))


@pytest.mark.parametrize("table, message", [
    ('true_parameters = "paper_leg.toml"\nperturbation = 0.1', "robot.perturbation: give either"),
    ("perturbation = 0.9", "robot.perturbation: must be ≤ 0.5, got 0.9"),
    ("perturbation_seed = 3", "robot.perturbation_seed: is the seed of a perturbation"),
    ('perturbaton = 0.1', "robot.perturbaton: unknown field (did you mean 'perturbation'?)"),
    ('true_parameters = "nope.toml"', "robot.true_parameters: file 'nope.toml' not found"),
])
def test_bad_robot_tables_are_one_line(tmp_path, table, message):
    with pytest.raises(InputError, match=re.escape(message)):
        load_scene(scene(tmp_path, table))


def test_static_scenes_refuse_another_true_robot(tmp_path):
    text = scene_path("paper_static_loading").read_text()
    with pytest.raises(InputError, match="only a dynamic scene simulates"):
        load_scene(scene(tmp_path, "perturbation = 0.05", base=text))


def test_the_prediction_carries_the_files_declared_uncertainty(tmp_path):
    """A file declaring its uncertainty: predicted_error includes it (wider than without)."""
    robot = paper_leg()
    from dataclasses import replace

    (tmp_path / "declared.toml").write_text(robot_toml(replace(
        robot, model_uncertainty=ModelUncertainty(0.05, 0.1, 0.003))))
    short = BASE.replace("duration_s = 1.5", "duration_s = 1.1")
    with_u = load_scene(scene(tmp_path, 'file = "declared.toml"', "u.toml", short))
    without = load_scene(scene(tmp_path, 'file = "paper_leg.toml"', "v.toml", short))
    a, _ = P.execute(with_u, ["predicted_error"])
    b, _ = P.execute(without, ["predicted_error"])
    pa, pb = a["predicted_error"], b["predicted_error"]
    assert "declared model uncertainty" in pa["model_uncertainty_source"]
    assert pa["dynamic"]["position_rms_m"] > 2 * pb["dynamic"]["position_rms_m"]
