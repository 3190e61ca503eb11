"""The commands on a URDF robot: estimate on the shipped 3-D example log, bad input → exit 2 with
one line naming the file and element, simulate of a 3-D scene (slow)."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys

import numpy as np
import pandas as pd
import pytest

pytest.importorskip("pinocchio")

LOG = "examples/spatial/leg_pokes.csv"
ROBOT = "robots/quadruped_leg.toml"


@pytest.fixture
def _cli(cli_inprocess):
    """``torquebench ARGS`` in-process (from ``cwd``, default unchanged): these check
    what the command answers, not the process; an interpreter start-up and import less per call."""
    return lambda *args, cwd=None: cli_inprocess(*args, cwd=cwd)


def test_estimate_example_log_locates_both_pokes(tmp_path, _cli):
    out = tmp_path / "est.csv"
    res = _cli("estimate", LOG, "--robot", ROBOT, "--out", str(out), "--json")
    assert res.returncode == 0, res.stderr
    summary = json.loads(res.stdout)
    assert [iv["link"] for iv in summary["intervals"]] == ["shank", "thigh"]
    assert summary["residual_noise_source"].startswith("log declaration")
    truth = pd.read_csv(LOG.replace(".csv", ".truth.csv"), keep_default_na=False, na_values=["nan", ""])
    est = pd.read_csv(out, keep_default_na=False, na_values=["nan", ""])
    for iv in summary["intervals"]:
        sel = (truth.link == iv["link"])
        true_l = truth.loc[sel, ["lx", "ly", "lz"]].to_numpy()[0]
        assert np.linalg.norm(np.array([iv["lx_m"], iv["ly_m"], iv["lz_m"]]) - true_l) < 2e-3
    on = truth.link.fillna("").to_numpy() != ""
    ok = (est.reason == "ok").to_numpy() & on                # the residual's decay after a poke: no truth
    assert ok.sum() > 0.9 * on.sum()
    assert (est.link.to_numpy()[ok] == truth.link.to_numpy()[ok]).all()
    ident = {d["link"]: d for d in summary["identifiability"]}
    assert ident["shank"]["sensed_joints_moving_it"] == ["hip_abd", "hip_flex", "knee"]


def test_bad_input_exits_2_naming_file_and_element(tmp_path, _cli):
    bad = tmp_path / "bad.urdf"
    bad.write_text("<robot name='x'><link name='a'>")
    res = _cli("estimate", LOG, "--robot", str(bad))
    assert res.returncode == 2 and str(bad) in res.stderr and len(res.stderr.strip().splitlines()) == 1
    shutil.copy("robots/quadruped_leg.urdf", tmp_path / "leg.urdf")
    decl = tmp_path / "leg.toml"
    decl.write_text('urdf = "leg.urdf"\nft_frame = "load_cell"\n')
    res = _cli("estimate", LOG, "--robot", str(decl))
    assert res.returncode == 2 and "ft_frame: no frame 'load_cell'" in res.stderr
    text = open(LOG).read().split("\n", 1)
    log = tmp_path / "renamed.csv"
    log.write_text(text[0].replace("q_knee", "q_knee_pitch") + "\n" + text[1])
    res = _cli("estimate", str(log), "--robot", ROBOT)
    assert res.returncode == 2 and "missing column 'q_knee'" in res.stderr and "renamed.csv" in res.stderr
    res = _cli("estimate", LOG, "--robot", ROBOT, "--method", "paper")
    assert res.returncode == 2 and "--method paper: not available for a URDF robot" in res.stderr


@pytest.mark.slow
def test_simulate_3d_scene(tmp_path, _cli):
    out = tmp_path / "leg.csv"
    res = _cli("simulate", "scenes/spatial/quadruped_leg_pokes.toml", "--out", str(out), "--duration", "0.4", "--json")
    assert res.returncode == 0, res.stderr
    assert json.loads(res.stdout)["samples"] == 401
    for side in ("leg.truth.csv", "leg.timing.toml", "leg.noise.toml"):
        assert (tmp_path / side).exists()
    head = out.read_text().split("\n", 1)[0]
    assert head.startswith("t,x,y,z,qx,qy,qz,qw,q_hip_abd") and head.endswith("Fx,Fy,Fz,Mx,My,Mz")


def _short_scene(tmp_path):
    text = open("scenes/spatial/quadruped_leg_pokes.toml").read()
    text = text.replace("duration_s = 1.2", "duration_s = 0.75").replace("substeps = 10", "substeps = 4")
    p = tmp_path / "short.toml"
    p.write_text(text)
    return p


@pytest.mark.slow
def test_run_and_sweep_on_a_3d_scene(tmp_path, _cli):
    """run: measured against the truth and predicted at the pokes; sweep/compare tabulate 3-D
    points with the planar keys (a noisier torque sensor: larger predicted error)."""
    scene = _short_scene(tmp_path)
    res = _cli("run", str(scene), "--json")
    assert res.returncode == 0, res.stderr
    out = json.loads(res.stdout)
    me, pr = out["measured"]["dynamic"], out["predicted"]["dynamic"]
    assert me["isolation_fraction"] > 0.95 and me["position_error_median_m"] < 2e-3
    assert me["false_alarm_fraction"] < 1e-3
    assert 0.3 < pr["position_rms_m"] / me["position_error_median_m"] < 3
    res = _cli("sweep", str(scene), "--vary", "sensors.torque_noise_Nm=0.001,0.05", "--executor", "local", "--json")
    assert res.returncode == 0, res.stderr
    pts = json.loads(res.stdout)["points"]
    assert [p["point"]["sensors.torque_noise_Nm"] for p in pts] == [0.001, 0.05]
    preds = [p["result"]["predicted"]["dynamic"]["position_rms_m"] for p in pts]
    assert preds[1] > preds[0]
