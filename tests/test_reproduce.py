"""The reproduction: one fast end-to-end CLI run, and the accuracy claims of the report as tests."""

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from torquebench.reports import reproduction as rr
from torquebench.scenes import load_scene

ROOT = Path(__file__).resolve().parents[1]


def test_reproduce_cli_end_to_end_quick(tmp_path, cli_inprocess):
    proc = subprocess.run([sys.executable, "-m", "torquebench", "reproduce", "--scene", "paper_fixed_link2",
                           "--scene", "paper_static_loading", "--quick", "--out-dir", str(tmp_path), "--json"],
                          capture_output=True, text=True, cwd=ROOT, env={"MPLBACKEND": "Agg", "PATH": ""})
    assert proc.returncode == 0, proc.stderr[-2000:]
    out = json.loads(proc.stdout)
    md = (tmp_path / "paper_reproduction.md").read_text()
    assert "Table V" in md and "Table IV" in md and "Stiffness" in md
    assert (tmp_path / "reproduction_paper_fixed_link2.png").stat().st_size > 10_000
    tab = out["tables"]["paper_fixed_link2"]
    assert tab["paper_table"]["mean"][5] == 0.002
    assert tab["dynamic"]["mean"]["|p|"] < 0.002          # Table V test 2: ≤ the paper's mean |p|
    stiff = out["stiffness"]
    assert any(r["status"] == "refused" and "unstable" in r["message"] for r in stiff)
    assert all(r["max_q_error_rad"] < 1e-4 for r in stiff if r["status"] == "ok")
    rows = out["tables"]["paper_static_loading"]
    assert [(r["link"], r["load_g"]) for r in rows] == [(1, 100), (1, 500), (2, 50), (2, 100)]
    bad = cli_inprocess("reproduce", "--scene", "nope", cwd=ROOT)       # the answer, not the process
    assert bad.returncode == 2 and "unknown scene" in bad.stderr


@pytest.fixture(scope="module")
def floating():
    from estimator.sim import simulate
    out = {}
    for name in ("paper_floating_link1", "paper_floating_link2"):
        scene = load_scene(ROOT / "scenes" / f"{name}.toml")
        out[name] = rr.evaluate_dynamic(scene, simulate(scene.sim), with_traces=False)
    return out


@pytest.mark.parametrize("name", ["paper_floating_link1", "paper_floating_link2"])
def test_table_iii_dynamic_halves_the_papers_mean_position_error(floating, name):
    r = floating[name]
    paper_mean_p = rr.PAPER_TABLE_III[name]["mean"][5]
    for m in ("dynamic", "dynamic + filter"):
        v = r["methods"][m]
        assert v["detected_in_phase"] > 0.99 and v["link_correct_in_phase"] > 0.99
        assert v["collision_phase"]["mean"][5] < paper_mean_p / 2
        assert v["collision_phase"]["mean"][2] < rr.PAPER_TABLE_III[name]["mean"][2]


def test_posture_sweep_meets_the_papers_bounds_and_flags_the_rest():
    res = rr.evaluate_static(load_scene(ROOT / "scenes" / "paper_posture_sweep.toml"))
    s = rr.sweep_summary(res)
    assert s["points"] == 800
    assert s["max_location_error_mm"] < 13.5
    assert s["max_force_error_N"] < 0.15
    assert s["flagged"] < 0.1 * s["points"]
    # flagged points come with a reason, never with a silently wrong location
    assert all(r != "ok" for r, f in zip(res["reason"], res["flagged"]) if f)


def test_causal_mean_skips_nans():
    x = np.array([1.0, np.nan, 3.0, 5.0])[:, None]
    assert np.allclose(rr.causal_mean(x, 2)[:, 0], [1.0, 1.0, 3.0, 4.0])
