"""Our simulator declares its sensor timing: the log writer puts LOG.timing.toml beside the log
(every force channel instantaneous), `estimate` reads it, and on a contact-free noise-free log with
a fast base transient the residual is at the observer's discretization level (second order in Δt)."""

from dataclasses import replace

import numpy as np
import pytest

from estimator import timing
from estimator.log_reader import read_log
from estimator.estimate import estimate
from estimator.robot import paper_leg
from estimator.sim import Controller, Sensors, SimConfig, simulate
from estimator.sim.output import log_files, timing_toml
from userio.files import write_files_atomic

ROBOT = paper_leg()
QUIET = Sensors(torque_noise_Nm=0.0, ft_noise=np.zeros(3))


def _written(tmp_path, rate_Hz=1000.0, name="log"):
    """Simulate 0.3 s (base dropping onto its springs: a 10 Hz bounce, joints swinging), write the
    files as the simulator's writer does, read the log back."""
    c = SimConfig(robot=ROBOT, duration_s=0.3, rtol=1e-9, atol=1e-11,
                  sensors=replace(QUIET, sample_rate_Hz=rate_Hz),
                  controller=Controller(q0_rad=np.array([-0.4, -0.8]), amplitude_rad=np.array([0.2, 0.3]),
                                        frequency_Hz=np.array([2.0, 3.0]), phase_rad=np.zeros(2)))
    res = simulate(c)
    out = tmp_path / f"{name}.csv"
    paths = write_files_atomic(log_files(out, res.log, res.truth, tmp_path / f"{name}.truth.csv"))
    return read_log(out, ROBOT), paths


@pytest.fixture(scope="module")
def written(tmp_path_factory):
    return _written(tmp_path_factory.mktemp("simtiming"))


def test_writer_puts_the_declaration_beside_the_log(written):
    log, paths = written
    assert [p.name for p in paths] == ["log.csv", "log.truth.csv", "log.timing.toml"]
    assert log.timing == timing.uniform("instant", 2)
    assert 'default = "instant"' in paths[2].read_text()


def test_estimate_reads_it_and_the_residual_stays_at_discretization_level(written, tmp_path):
    log, _ = written
    est = estimate(ROBOT, log)
    assert est.info["timing_source"] == "log declaration"
    assert est.info["timing"] == "instant"
    assert not est.contact.any()
    r = np.linalg.norm(est.residual, axis=1)
    wrong = np.linalg.norm(estimate(ROBOT, log, timing="mean").residual, axis=1)
    # the same log at 2 kHz: the trapezoid's error is second order in Δt
    fine, _ = _written(tmp_path, 2000.0, "fine")
    r_fine = np.linalg.norm(estimate(ROBOT, fine).residual, axis=1)
    order = np.log2(r.max() / r_fine.max())
    print(f"max ‖r‖: declared {r.max():.3g} (2 kHz {r_fine.max():.3g}, order {order:.2f}), "
          f"mis-declared 'mean' {wrong.max():.3g}")
    assert r.max() < 0.005 < 0.06                  # far below the paper's ε
    assert wrong.max() > 50 * r.max()              # what a wrong declaration costs
    assert 1.6 < order < 2.4


def test_a_declared_log_keeps_its_declaration():
    from estimator.log import SensorLog

    z = np.zeros((3, 5))
    log = SensorLog(t=np.arange(3) * 1e-3, q=z, dq=z, tau_Nm=z[:, :2], wrench=z[:, :3])
    log.timing = [("mean", 0.0)] * 3 + [("delay", 5e-4)] * 2
    text = timing_toml(log)
    import tomllib

    table = tomllib.loads(text)["timing"]
    assert table["Fx"] == "mean" and table["tau2"] == "delay:0.0005"



def test_simulate_command_writes_the_declaration_with_the_log(tmp_path, capsys):
    """`torquebench simulate` writes log, truth and timing declaration as one set, and `estimate`
    on that log reads the declaration (no --timing needed)."""
    import json

    from torquebench.cli import main

    out = tmp_path / "sim" / "log.csv"
    assert main(["simulate", "scenes/paper_fixed_link2.toml", "--out", str(out), "--json",
                 "--duration", "0.3"]) == 0
    sim = json.loads(capsys.readouterr().out)
    timing = tmp_path / "sim" / "log.timing.toml"
    assert sim["timing"] == str(timing) and 'default = "instant"' in timing.read_text()
    assert main(["estimate", str(out), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["timing_source"] == "log declaration"
