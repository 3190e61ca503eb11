"""Sweeps: identical results whatever the executor; a failing point is reported, the others kept;
a rerun resumes from the cache."""

from __future__ import annotations

from pathlib import Path

import pytest

from torquebench.sweep import parse_vary, run_sweep

ROOT = Path(__file__).resolve().parents[1]
SCENE = ROOT / "scenes" / "paper_floating_link2.toml"
VARY = parse_vary(["poke.1.alpha=0.5,2.0", "sensors.seed=1,2"])
OUT = ["localization_error"]


def _results(rows):
    return [(r["point"], r.get("result", {}).get("measured"), r.get("error")) for r in rows]


@pytest.fixture(scope="module")
def local(tmp_path_factory):
    return run_sweep(SCENE, VARY, OUT, "local", str(tmp_path_factory.mktemp("c_local")))


def test_failing_point_reported_others_kept(local):
    assert len(local) == 4
    bad = [r for r in local if "error" in r]
    assert len(bad) == 2 and all(r["point"]["poke.1.alpha"] == 2.0 for r in bad)
    assert all("poke[1].alpha" in r["error"] for r in bad)
    good = [r for r in local if "error" not in r]
    assert all(r["result"]["measured"]["dynamic"]["scored_samples"] > 0 for r in good)
    a, b = (r["result"]["measured"]["dynamic"]["position_error_rms_m"] for r in good)
    assert a != b                      # the seed is part of the point


def test_process_pool_gives_identical_results_and_resumes_from_cache(local, tmp_path):
    rows = run_sweep(SCENE, VARY, OUT, "processes:2", str(tmp_path))
    assert _results(rows) == _results(local)
    again = run_sweep(SCENE, VARY, OUT, "local", str(tmp_path))
    assert _results(again) == _results(local)
    assert all(set(r["stages"].values()) == {"cached"} for r in again if "error" not in r)


def test_dask_local_cluster_gives_identical_results(local, tmp_path):
    distributed = pytest.importorskip("distributed")
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as cluster:
        rows = run_sweep(SCENE, VARY, OUT, f"dask://{cluster.scheduler_address.removeprefix('tcp://')}",
                         str(tmp_path))
    assert _results(rows) == _results(local)


def test_bad_vary_and_executor_are_input_errors():
    from userio.errors import InputError

    with pytest.raises(InputError, match="--vary"):
        parse_vary(["poke.1.alpha"])
    with pytest.raises(InputError, match="--executor"):
        run_sweep(SCENE, VARY, OUT, "threads:2", None)


def test_shared_upstream_stages_are_computed_once_before_fanning_out(tmp_path):
    """Only the seed varies: the first point runs alone and computes the simulation (and sensor
    chain) every point shares; no worker computes them again. The noise (raw_counts) is per point."""
    info = {}
    rows = run_sweep(SCENE, parse_vary(["sensors.seed=1,2,3"]), OUT, "processes:2", str(tmp_path), info=info)
    assert "simulation" in info["shared_stages"] and "raw_counts" not in info["shared_stages"]
    assert [r["stages"]["simulation"] for r in rows] == ["run", "cached", "cached"]
    assert [r["stages"]["raw_counts"] for r in rows] == ["run", "run", "run"]
