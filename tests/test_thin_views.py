"""`simulate`, `propagate` and `reproduce` are views over the stage graph: each builds a scene and
asks torquebench.pipeline for its stages, so each stage is computed (and cached) in one place.
References: the simulator's and the reproduction's own entry points, called directly."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import pytest

from torquebench import pipeline as P
from torquebench.cache import Cache
from torquebench.cli import main
from torquebench.scenes import load_scene, with_overrides, with_seed

ROOT = Path(__file__).resolve().parents[1]
SCENES = ROOT / "scenes"


@pytest.fixture
def cache_dir(tmp_path, monkeypatch):
    d = tmp_path / "cache"
    monkeypatch.setenv("TORQUEBENCH_CACHE", str(d))
    return d


def test_simulate_writes_the_simulators_own_log_and_shares_the_simulation_stage(tmp_path, cache_dir, capsys):
    from estimator.sim import simulate
    from estimator.sim.output import log_csv, truth_csv

    out = tmp_path / "log.csv"
    assert main(["simulate", str(SCENES / "paper_fixed_link1.toml"), "--out", str(out), "--seed", "5",
                 "--duration", "0.3", "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    scene = with_overrides(with_seed(load_scene(SCENES / "paper_fixed_link1.toml"), 5), duration_s=0.3)
    ref = simulate(scene.sim)                    # the simulator called directly, noise included
    assert out.read_text() == log_csv(ref.log)
    assert (tmp_path / "log.truth.csv").read_text() == truth_csv(ref.truth)
    assert doc["samples"] == len(ref.t) and doc["q_rad_error_estimate"] == ref.stats["q_rad_error_estimate"]
    # `run` on the same scene finds the simulation simulate computed; only the noise is new
    steps = {s.stage.name: s.action for s in P.plan(scene, ["localization_error"], Cache(cache_dir))}
    assert steps["simulation"] == "cached" and steps["raw_counts"] == "run"


def test_simulate_static_scene_is_the_static_holds_stage(tmp_path, cache_dir, capsys):
    from estimator.sim.output import log_csv
    from estimator.sim.static import static_hold_log

    out = tmp_path / "s.csv"
    assert main(["simulate", str(SCENES / "paper_static_loading.toml"), "--out", str(out), "--seed", "3"]) == 0
    st = with_seed(load_scene(SCENES / "paper_static_loading.toml"), 3).static
    pts = st.points
    log, _, _ = static_hold_log(st.robot, np.array([p.q_rad for p in pts]), np.array([p.link for p in pts]),
                                np.array([p.alpha for p in pts]), np.array([p.force_N for p in pts]),
                                st.sensors, st.hold_s, tare_s=0.3)
    assert out.read_text() == log_csv(log)


def _propagate_args(*argv):
    from torquebench.commands import propagate

    ap = argparse.ArgumentParser()
    propagate.add_arguments(ap)
    return ap.parse_args(list(argv))


def test_propagate_is_the_error_map_stage_and_is_cached(cache_dir, capsys):
    from estimator.robot import paper_leg
    from torquebench.commands.propagate import scene_from_args

    argv = ["--grid", "3", "--draws", "50", "--calibration", str(ROOT / "calibration/data/paper_link1_cal.json")]
    assert main(["propagate", *argv, "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    args = _propagate_args(*argv)
    scene = scene_from_args(args, paper_leg(), 2, 0.8, 7.0, -np.pi / 3)
    steps = {s.stage.name: s for s in P.plan(scene, ["error_map"], Cache(cache_dir))}
    assert steps["error_map"].action == "cached" and steps["sensor_chain"].action == "cached"
    assert steps["simulation"].action == "skip" and steps["calibration_fit"].action == "skip"
    arts, _ = P.execute(scene, ["error_map"], Cache(cache_dir))
    assert doc["methods"] == json.loads(json.dumps(arts["error_map"]["methods"]))
    assert doc["gain_error_rel_std"] > 0 and doc["strain_per_Nm"] == arts["chain"].strain_per_Nm
    # a given σ_τ and gain error: neither the sensor chain nor the calibration is read
    given = scene_from_args(_propagate_args("--torque-noise-Nm", "0.02", "--gain-error", "0.01",
                                            "--calibration", "no/such.json"),
                            paper_leg(), 2, 0.8, 7.0, -np.pi / 3)
    acts = {s.stage.name: s.action for s in P.plan(given, ["error_map"], None)}
    assert acts["sensor_chain"] == "skip" and acts["error_map"] == "run"


def test_reproduce_scores_are_the_stage_graphs_and_equal_a_direct_simulation(cache_dir):
    """The reproduction asks the stage graph for each scene's paper_scores (one assembly, shared
    by `reproduce` and the report builder); its scores equal those of the simulator run directly
    with the scene's noisy sensors (an independent path: noise drawn inside the simulation, not by
    sensor_log afterwards) and of the static holds computed directly."""
    from estimator.sim import simulate
    from torquebench.reports import reproduction as rr
    from torquebench.stages.paper import evaluate_dynamic, evaluate_static

    names = ["paper_fixed_link2", "paper_static_loading"]
    ours = rr.results(names, stiffness=False, progress=False, cache=Cache(cache_dir))
    scene = load_scene(SCENES / "paper_fixed_link2.toml")
    ref = evaluate_dynamic(scene, simulate(scene.sim))
    a, b = ours["dynamic"]["paper_fixed_link2"], ref
    for m in ("dynamic", "paper", "dynamic + filter"):
        assert a["methods"][m]["collision_phase"] == b["methods"][m]["collision_phase"]
    a = ours["static"]["paper_static_loading"]
    b = evaluate_static(load_scene(SCENES / "paper_static_loading.toml"))
    assert np.array_equal(a["location_error_m"], b["location_error_m"], equal_nan=True)
    # a second run reads every scene's scores from the stage cache
    steps = {s.stage.name: s.action for s in P.plan(scene, ["paper_scores"], Cache(cache_dir))}
    assert steps["paper_scores"] == "cached" and steps["sensor_log"] == "cached"
    static = load_scene(SCENES / "paper_static_loading.toml")
    steps = {s.stage.name: s.action for s in P.plan(static, ["paper_scores"], Cache(cache_dir))}
    assert steps["paper_scores"] == "cached" and steps["static_holds"] == "cached"


def test_simulate_refuses_a_scene_that_reads_a_recorded_log(tmp_path, cache_dir, capsys):
    (tmp_path / "l.csv").write_text("t,q1,q2,dq1,dq2,tau1,tau2,Fx,Fz,My\n")
    scene = tmp_path / "s.toml"
    scene.write_text('robot = "paper_leg.toml"\n[source]\nlog = "l.csv"\n')
    assert main(["simulate", str(scene), "--out", str(tmp_path / "x.csv")]) == 2
    err = capsys.readouterr().err
    assert "s.toml: source.log: the scene reads a recorded log" in err and err.count("\n") == 1
