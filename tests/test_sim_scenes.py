"""Scene files: the shipped ones load; bad fields are InputErrors naming file and field; simulate CLI."""

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from userio.errors import InputError
from torquebench.scenes import load_scene

ROOT = Path(__file__).resolve().parents[1]
SHIPPED = ["paper_floating_link1", "paper_floating_link2", "paper_fixed_link1", "paper_fixed_link2",
           "paper_static_loading", "paper_posture_sweep", "moving_leg"]


@pytest.mark.parametrize("name", SHIPPED)
def test_shipped_scenes_load(name):
    s = load_scene(ROOT / "scenes" / f"{name}.toml")
    assert s.name == name
    if s.sim is not None:
        assert s.sim.pokes and s.sim.duration_s > 0
    else:
        assert len(s.static.points) in (16, 800)


def test_paper_scene_parameters():
    s = load_scene(ROOT / "scenes" / "paper_floating_link2.toml").sim
    p = s.pokes[0]
    assert (p.link, p.alpha, p.magnitude_N) == (2, 0.8, 7.0)
    assert p.direction_rad == pytest.approx(-np.pi / 3)
    assert s.controller.kp == 500 and s.controller.kd == 10
    assert np.allclose(s.robot.base_stiffness, [5000, 5000, 500])
    assert np.allclose(s.sensors.ft_noise, [0.1, 0.1, 0.01])


BAD = [
    ("[controller]\nq0_rad = [0.1]\n", "controller.q0_rad"),
    ("[controller]\nq0_rad = [0.1, 0.2]\nmode = \"hold\"\n", "controller.mode"),
    ("[controller]\nq0_rad = [0.1, 0.2]\n[[poke]]\nlink = 3\nalpha = 0.5\nmagnitude_N = 1\ndirection_rad = 0\n", "poke[1].link"),
    ("[controller]\nq0_rad = [0.1, 0.2]\n[[poke]]\nlink = 1\nalpha = 1.5\nmagnitude_N = 1\ndirection_rad = 0\n", "poke[1].alpha"),
    ("[controller]\nq0_rad = [0.1, 0.2]\n[[poke]]\nlink = 1\nalpha = 0.5\nmagnitude_N = 1\ndirection_rad = 0\nt_on_s = 0.5\nt_off_s = 0.2\n", "poke[1].t_off_s"),
    ("[controller]\nq0_rad = [0.1, 0.2]\n[integrator]\nmethod = \"Euler\"\n", "integrator.method"),
    ("[controller]\nq0_rad = [0.1, 0.2]\n[sensors]\nft_noise = [0.1, -0.1, 0.01]\n", "sensors.ft_noise"),
    ("[controller]\nq0_rad = [0.1, 0.2]\ncolour = 3\n", "colour"),
    ("duration_s = -1\n[controller]\nq0_rad = [0.1, 0.2]\n", "duration_s"),
    ("robot = \"nope.toml\"\n[controller]\nq0_rad = [0.1, 0.2]\n", "robot"),
    ("[controller\n", "invalid TOML"),
]


@pytest.mark.parametrize("text,field", BAD)
def test_bad_scene_fields_name_file_and_field(tmp_path, text, field):
    path = tmp_path / "bad.toml"
    path.write_text(text)
    with pytest.raises(InputError) as exc:
        load_scene(path)
    assert str(path) in str(exc.value) and field in str(exc.value)


@pytest.fixture
def _cli(cli_inprocess):
    """``torquebench ARGS`` in-process (from ``cwd``, default the repository root): these check
    what the command answers, not the process; an interpreter start-up and import less per call."""
    return lambda *args, cwd=ROOT: cli_inprocess(*args, cwd=cwd)


def test_simulate_cli_writes_log_and_truth(tmp_path, _cli):
    out = tmp_path / "leg.csv"
    proc = _cli("simulate", "scenes/paper_fixed_link2.toml", "--out", str(out), "--duration", "0.6",
                "--json")
    assert proc.returncode == 0, proc.stderr
    summary = json.loads(proc.stdout)
    log = pd.read_csv(out)
    truth = pd.read_csv(tmp_path / "leg.truth.csv")
    assert list(log.columns) == ["t", "q1", "q2", "dq1", "dq2", "tau1", "tau2", "Fx", "Fz", "My"]
    assert list(truth.columns) == ["t", "link", "alpha", "Fx", "Fz", "px", "pz"]
    assert len(log) == len(truth) == summary["samples"] == 601
    on = truth.link.values > 0
    assert on.sum() == summary["contact_samples"] == 101   # t = 0.5 … 0.6 inclusive
    assert np.allclose(np.hypot(truth.Fx[on], truth.Fz[on]), 7.0)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["leg.csv", "leg.noise.toml", "leg.timing.toml",
                                                           "leg.truth.csv"]
    assert summary["noise"] == str(tmp_path / "leg.noise.toml")


def test_simulate_cli_reads_back_through_the_estimator(tmp_path, _cli):
    from estimator.log_reader import read_log
    from estimator.robot import paper_leg

    out = tmp_path / "f.csv"
    assert _cli("simulate", "scenes/paper_floating_link1.toml", "--out", str(out), "--duration", "0.3").returncode == 0
    log = read_log(out, paper_leg())
    assert log.floating and log.q.shape == (301, 5)


def test_simulate_cli_refuses_bad_input(tmp_path, _cli):
    scene = tmp_path / "s.toml"
    scene.write_text((ROOT / "scenes" / "paper_fixed_link1.toml").read_text())
    before = scene.read_text()
    proc = _cli("simulate", str(scene), "--out", str(scene))
    assert proc.returncode == 2 and "refusing to overwrite" in proc.stderr
    assert len(proc.stderr.strip().splitlines()) == 1 and scene.read_text() == before
    zoh = tmp_path / "zoh.toml"
    zoh.write_text(before.replace('mode = "continuous"', 'mode = "zoh"\nrate_Hz = 1000.0'))
    proc = _cli("simulate", str(zoh), "--out", str(tmp_path / "z.csv"))
    assert proc.returncode == 2 and "unstable" in proc.stderr and "Hz" in proc.stderr
    assert len(proc.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "z.csv").exists()
    proc = _cli("simulate", str(tmp_path / "missing.toml"), "--out", str(tmp_path / "m.csv"))
    assert proc.returncode == 2 and "missing.toml" in proc.stderr


def test_noise_free_simulation_declares_no_noise(tmp_path, _cli):
    """A scene whose sensors draw no noise has nothing to whiten with: no LOG.noise.toml, and an
    old one beside --out --force is not left behind to describe the new log."""
    root = Path(__file__).resolve().parents[1]
    text = (root / "scenes" / "paper_fixed_link2.toml").read_text()
    text = text.replace('robot = "paper_leg.toml"', f'robot = "{root / "robots" / "paper_leg.toml"}"')
    text = text.replace('torque_model = "bridge"', 'torque_model = "gaussian"\ntorque_noise_Nm = 0.0')
    text = text.replace("ft_noise = [0.1, 0.1, 0.01]", "ft_noise = [0.0, 0.0, 0.0]")
    (tmp_path / "quiet.toml").write_text(text)
    out = tmp_path / "leg.csv"
    (tmp_path / "leg.noise.toml").write_text("[noise]\n")
    proc = _cli("simulate", str(tmp_path / "quiet.toml"), "--out", str(out), "--duration", "0.2",
                "--json", "--force")
    assert proc.returncode == 0, proc.stderr
    assert json.loads(proc.stdout)["noise"] is None
    assert not (tmp_path / "leg.noise.toml").exists()
