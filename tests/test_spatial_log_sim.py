"""The 3-D log contract (write → read round trip, header errors naming the column, timing and
noise side files) and the URDF simulator (the observer's residual equals the applied external
generalized force once settled, on a floating and on a fixed base)."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("pinocchio")

from userio.errors import InputError  # noqa: E402
from estimator.spatial import model as mm  # noqa: E402
from estimator.spatial.logs import (SpatialLogReader, make_noise, noise_text, read_noise,  # noqa: E402
                                    read_spatial_log, read_timing, spatial_columns,
                                    write_spatial_log)
from estimator.spatial.model import UrdfModel  # noqa: E402
from estimator.spatial.observer import residual  # noqa: E402
from estimator.spatial.robot import load_spatial_robot  # noqa: E402
from estimator.spatial.sim import Poke, SimSpec, simulate  # noqa: E402

POKE = Poke("shank", np.array([0.012, 0.0, -0.12]), np.array([-4.0, 1.0, 2.0]), 0.15, 0.35)


@pytest.fixture(scope="module")
def leg():
    robot = load_spatial_robot("robots/quadruped_leg.toml")
    return robot, UrdfModel(robot)


@pytest.fixture(scope="module", params=[True, False], ids=["floating", "fixed"])
def run(request, leg):
    robot = leg[0].with_base(request.param)
    model = UrdfModel(robot)
    spec = SimSpec(duration_s=0.35, substeps=4, q0_rad=np.array([0.2, 0.6, -1.2]), pokes=[POKE])
    log, truth, _ = simulate(robot, spec)
    return robot, model, log, truth


def test_columns_contract(leg):
    robot, _ = leg
    cols = spatial_columns(robot.joint_names, robot.sensed, True)
    assert cols[:8] == ["t", "x", "y", "z", "qx", "qy", "qz", "qw"]
    assert cols[-6:] == ["Fx", "Fy", "Fz", "Mx", "My", "Mz"]
    assert "tau_knee" in cols and "dq_hip_abd" in cols and "wz" in cols
    assert spatial_columns(robot.joint_names, (True, False, True), False)[:4] == ["t", "q_hip_abd", "q_hip_flex", "q_knee"]
    assert "tau_hip_flex" not in spatial_columns(robot.joint_names, (True, False, True), False)


def test_residual_equals_external_force(run):
    robot, model, log, truth = run
    r = residual(model, log.t, log.q, log.v, log.tau_meas(model))
    k = 340                                              # 0.19 s into the poke: settled (K = 100/s)
    S, *_ = mm.columns(model.tree, log.q[k:k + 1])
    p = truth[["px", "py", "pz"]].to_numpy()[k] - log.q[k, :3]
    F = truth[["Fx", "Fy", "Fz"]].to_numpy()[k]
    tau_ext = S[0] @ np.r_[F, np.cross(p, F)] * mm.moves(model.tree)[:, 3]
    assert np.allclose(r[k], tau_ext, atol=2e-3 * np.abs(tau_ext).max())
    assert np.abs(r[50:149]).max() < 1e-3               # before the poke: nothing
    assert (truth["link"].iloc[200] == "shank") and truth["link"].iloc[100] == ""


@pytest.mark.parametrize("suffix", [".csv", ".parquet"])
def test_log_round_trip_and_chunks(run, tmp_path, suffix):
    robot, model, log, _ = run
    path = tmp_path / f"leg{suffix}"
    write_spatial_log(log, robot, path)
    back = read_spatial_log(path, robot, model)
    assert back.floating == robot.floating
    for f in ("t", "q", "v", "tau_Nm", "wrench"):
        assert np.array_equal(getattr(back, f), getattr(log, f)), f
    parts = list(SpatialLogReader(path, robot, model, chunk_samples=50))
    assert sum(len(p.t) for p in parts) == len(log.t) and np.array_equal(np.concatenate([p.q for p in parts]), log.q)


def test_header_errors_name_the_column(run, tmp_path):
    robot, model, log, _ = run
    path = tmp_path / "leg.csv"
    write_spatial_log(log, robot, path)
    text = path.read_text().split("\n", 1)
    (tmp_path / "bad.csv").write_text(text[0].replace("q_knee", "q_knee_joint", 1) + "\n" + text[1])
    with pytest.raises(InputError, match="bad.csv: line 1: missing column 'q_knee' \\(found 'q_knee_joint'"):
        read_spatial_log(tmp_path / "bad.csv", robot, model)
    (tmp_path / "bad2.csv").write_text(text[0] + ",tau_elbow\n" + text[1].replace("\n", ",0\n"))
    with pytest.raises(InputError, match="column 'tau_elbow': 'elbow' is not a joint"):
        read_spatial_log(tmp_path / "bad2.csv", robot, model)


def test_timing_and_noise_side_files(leg, tmp_path):
    robot, _ = leg
    log = tmp_path / "x.csv"
    (tmp_path / "x.timing.toml").write_text('[timing]\nwrench = "mean"\ntau_knee = "delay:0.001"\n')
    spec = read_timing(log, robot)
    assert spec[:6] == [("mean", 0.0)] * 6 and spec[8] == ("delay", 0.001) and spec[6] == ("instant", 0.0)
    (tmp_path / "x.timing.toml").write_text('[timing]\nFx = "mean"\n')
    with pytest.raises(InputError, match="six wrench channels"):
        read_timing(log, robot)
    (tmp_path / "x.timing.toml").write_text('[timing]\ntau_kne = "mean"\n')
    with pytest.raises(InputError, match="did you mean 'tau_knee'"):
        read_timing(log, robot)
    noise = make_noise(0.005, [0.1, 0.01], 3)
    (tmp_path / "x.noise.toml").write_text(noise_text(noise))
    back = read_noise(log, robot)
    assert np.allclose(back.ft_sigma, [0.1] * 3 + [0.01] * 3) and np.allclose(back.torque_sigma_Nm, 0.005)
    (tmp_path / "x.noise.toml").write_text("[noise]\ntorque_sigma_Nm = [0.005]\nft_sigma = [0.1, 0.1, 0.1, 0.01]\n")
    with pytest.raises(InputError, match="noise.ft_sigma: expected 2 or 6 values, got 4"):
        read_noise(log, robot)


def test_streaming_observer_and_chunked_pipeline_match_offline(run):
    """One sample at a time (StreamingObserver) and the pipeline fed in chunks of 37 samples
    give the offline numbers (the same arithmetic)."""
    from estimator.spatial.observer import StreamingObserver
    from estimator.spatial.pipeline import estimate_log

    robot, model, log, _ = run
    tau = log.tau_meas(model)
    r = residual(model, log.t, log.q, log.v, tau)
    obs = StreamingObserver(model, 1e-3)
    rs = np.array([obs.step(log.q[k], log.v[k], tau[k]).copy() for k in range(len(log.t))])
    assert np.allclose(rs, r, rtol=0, atol=1e-12 * np.abs(r).max())
    one = estimate_log(model, [log], 1e-3)
    many = estimate_log(model, [log.slice(slice(s, s + 37)) for s in range(0, len(log.t), 37)], 1e-3)
    a, b = one.frame, many.frame
    assert (a.contact == b.contact).all() and (a.reason == b.reason).all()
    num = ["px", "py", "pz", "Fx", "Fy", "Fz", "rnorm"]
    assert np.allclose(a[num].to_numpy(), b[num].to_numpy(), rtol=1e-12, atol=1e-15, equal_nan=True)
