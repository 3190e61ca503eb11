"""Robot descriptions: the paper's leg loads as Table I says; bad files name the field."""

import re

import numpy as np
import pytest

from userio.errors import InputError
from estimator.robot import PAPER_LEG_TOML, load_robot, paper_leg, robot_from_dict
from userio.files import read_toml


def test_paper_leg_matches_table_one():
    robot = paper_leg()
    np.testing.assert_array_equal(robot.lengths_m, [0.205, 0.215])
    np.testing.assert_array_equal(robot.com_m, [0.171, 0.031])
    np.testing.assert_array_equal(robot.masses_kg, [0.351, 0.080])
    np.testing.assert_array_equal(robot.inertias_kgm2, [0.00207, 0.00030])
    assert robot.base_mass_kg == 0.738 and robot.base_inertia_kgm2 == 0.002
    np.testing.assert_array_equal(robot.base_stiffness, [5000, 5000, 500])
    np.testing.assert_array_equal(robot.base_damping, [50, 50, 20])
    assert robot.floating and robot.n_coords == 5
    assert not paper_leg(floating=False).floating and paper_leg(floating=False).n_coords == 2


def _paper_dict():
    return read_toml(PAPER_LEG_TOML)


@pytest.mark.parametrize("mutate, message", [
    (lambda d: d["link"][1].__setitem__("mass_kg", -0.08), "link[2].mass_kg: must be > 0"),
    (lambda d: d["link"][0].__setitem__("inertia_kgm2", 0.0), "link[1].inertia_kgm2: must be > 0"),
    (lambda d: d["link"][0].pop("length_m"), "link[1].length_m: missing field"),
    (lambda d: d["base_body"].__setitem__("mass_kg", "heavy"), "base_body.mass_kg: expected a finite number"),
    (lambda d: d.__setitem__("base", "wobbly"), "base: must be 'floating' or 'fixed', got 'wobbly'"),
    (lambda d: d.pop("link"), "link: missing field"),
    (lambda d: d["base_mount"].__setitem__("stiffness", [1.0, 2.0]), "base_mount.stiffness: expected 3 numbers, got 2"),
    (lambda d: d["base_mount"].__setitem__("damping", [1.0, -2.0, 3.0]), "base_mount.damping[2]: must be ≥ 0"),
    # hostile input: misspelled keys, COM off its link, lists for numbers, inf
    (lambda d: d.__setitem__("friction_coeficient", 0.5), "friction_coeficient: unknown field (did you mean 'friction_coefficient'?)"),
    (lambda d: d.__setitem__("gravity_m_per_s", 9.81), "gravity_m_per_s: unknown field (did you mean 'gravity_m_per_s2'?)"),
    (lambda d: d["link"][0].__setitem__("mas_kg", 1.0), "link[1].mas_kg: unknown field (did you mean 'mass_kg'?)"),
    (lambda d: d["base_body"].__setitem__("inertia", 1.0), "base_body.inertia: unknown field"),
    (lambda d: d["link"][0].__setitem__("com_m", 0.3), "link[1].com_m: centre of mass 0.3 m lies beyond"),
    (lambda d: d["link"][1].__setitem__("com_m", -0.01), "link[2].com_m: must be ≥ 0"),
    (lambda d: d["link"][0].__setitem__("mass_kg", [0.3, 0.4]), "link[1].mass_kg: expected a finite number"),
    (lambda d: d["link"][0].__setitem__("length_m", float("inf")), "link[1].length_m: expected a finite number"),
    (lambda d: d.__setitem__("gravity_m_per_s2", 1e6), "gravity_m_per_s2: 1e+06 m/s² is outside the physical range [1, 30] m/s²"),
    (lambda d: d.__setitem__("base_mount", 3), "base_mount: expected a table"),
    (lambda d: d["link"].__setitem__(0, 5), "link[1]: expected a table"),
])
def test_bad_robot_fields_are_named(mutate, message):
    data = _paper_dict()
    mutate(data)
    with pytest.raises(InputError, match=re.escape(message)):
        robot_from_dict(data, source="leg.toml")


def test_any_number_of_links(tmp_path):
    data = _paper_dict()
    data["link"].append(dict(data["link"][1]))
    path = tmp_path / "three.toml"
    import tomllib  # noqa: F401  (the file is written by hand below, TOML has no stdlib writer)
    text = PAPER_LEG_TOML.read_text() + "\n[[link]]\nlength_m = 0.1\ncom_m = 0.05\nmass_kg = 0.05\ninertia_kgm2 = 0.0001\n"
    path.write_text(text)
    robot = load_robot(path)
    assert robot.n_links == 3 and robot.n_coords == 6


def test_invalid_toml_names_file_and_line(tmp_path):
    path = tmp_path / "broken.toml"
    path.write_text("name = 'x'\n[[link]\n")
    with pytest.raises(InputError, match=r"broken.toml: invalid TOML.*line 2"):
        load_robot(path)


def test_com_exactly_at_link_ends_is_accepted():
    data = _paper_dict()
    data["link"][0]["com_m"] = 0.0
    data["link"][1]["com_m"] = data["link"][1]["length_m"]
    robot = robot_from_dict(data, source="leg.toml")
    assert robot.com_m[0] == 0.0 and robot.com_m[1] == robot.lengths_m[1]


def test_non_utf8_robot_toml_is_one_line_error(tmp_path):
    path = tmp_path / "latin1.toml"
    path.write_bytes("name = 'B\xe9in'\n".encode("latin-1"))
    with pytest.raises(InputError, match="not UTF-8"):
        load_robot(path)
