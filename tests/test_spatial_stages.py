"""3-D scenes in the stage graph (torquebench.stages.spatial): planned with their own stages only,
cached (a second run computes nothing and gives the same results; a new seed re-runs the
simulation and what reads it, not the prediction), explained by `run --explain`, and a planar
scene never plans a 3-D stage."""

from __future__ import annotations

from pathlib import Path

import pytest

pytest.importorskip("pinocchio")

from torquebench import pipeline as P  # noqa: E402
from torquebench.cache import Cache  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
SCENE = ROOT / "scenes" / "spatial" / "quadruped_leg_pokes.toml"
SHORT = {"duration_s": 0.25, "integrator.substeps": 1, "poke.1.t_on_s": 0.1, "poke.1.t_off_s": 0.2}
SPATIAL = {"spatial_simulation", "spatial_estimation", "spatial_comparison", "spatial_prediction"}


def test_a_3d_scene_plans_its_own_stages_and_a_planar_one_none_of_them():
    from estimator.spatial.scene import load_spatial_scene
    from torquebench.scenes import load_scene

    steps = P.plan(load_spatial_scene(SCENE, SHORT), None, None)
    assert {s.stage.name for s in steps} == SPATIAL
    assert all(s.action == "run" for s in steps)
    only = P.plan(load_spatial_scene(SCENE, SHORT), ["spatial_predicted_error"], None)
    assert {s.stage.name for s in only if s.action == "run"} == {"spatial_prediction"}
    planar = P.plan(load_scene(ROOT / "scenes" / "end_to_end.toml"), None, None)
    assert not {s.stage.name for s in planar} & SPATIAL


@pytest.mark.slow
def test_3d_stages_are_cached_and_keyed_by_what_they_read(tmp_path):
    from torquebench.spatial_scene import run_scene_stages

    cache = Cache(tmp_path / "cache")
    first, t1 = run_scene_stages(SCENE, SHORT, cache=cache)
    again, t2 = run_scene_stages(SCENE, SHORT, cache=cache)
    assert {n for n, a, _ in t1 if a == "run"} == SPATIAL
    assert {a for _, a, _ in t2} == {"cached"}
    first.pop("run_time_s"), again.pop("run_time_s")
    assert first == again
    assert first["measured"]["dynamic"]["contact_samples"] == 100
    _, t3 = run_scene_stages(SCENE, SHORT, seed=7, cache=cache)          # new sensor noise
    assert {n for n, a, _ in t3 if a == "run"} == SPATIAL - {"spatial_prediction"}
    _, t4 = run_scene_stages(SCENE, {**SHORT, "poke.1.magnitude_N": 4.0}, cache=cache)
    assert {n for n, a, _ in t4 if a == "run"} == SPATIAL                # the pokes: everything


def test_run_explains_a_3d_scene(tmp_path, monkeypatch, capsys):
    from torquebench.cli import main

    monkeypatch.setenv("TORQUEBENCH_CACHE", str(tmp_path / "cache"))
    assert main(["run", str(SCENE), "--explain"]) == 0
    out = capsys.readouterr().out
    assert [line.split()[0] for line in out.splitlines()] == ["spatial_simulation", "spatial_estimation",
                                                              "spatial_comparison", "spatial_prediction"]
    assert main(["run", str(SCENE), "--explain", "--only", "noise_budget"]) == 2
