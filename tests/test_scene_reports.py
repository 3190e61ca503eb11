"""`report` as a stage: a scene asks for reports in [outputs]; only the builders whose inputs the
scene computes run, into the scene's output directory, never the shipped reports/ unless asked."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

STATIC = """name = "rep_scene"
robot = "paper_leg.toml"
kind = "static_loading"
q_rad = [0.3, 0.5]
[[load]]
link = 2
mass_kg = [0.1]
alpha = [0.5]
[flexure]
strain_per_Nm = 5e-5
"""


def _scene(tmp_path, outputs: str) -> Path:
    p = tmp_path / "scene.toml"
    p.write_text(STATIC + "[outputs]\n" + outputs)
    return p


def _cli(*args, cwd=ROOT):
    return subprocess.run([sys.executable, "-m", "torquebench", *args], capture_output=True, text=True,
                          cwd=cwd, env=None)


def _report_row(r):
    assert r.returncode == 0, r.stderr
    return next(s for s in json.loads(r.stdout)["stages"] if s["stage"] == "report")


def test_explain_lists_only_the_builders_whose_inputs_the_scene_has(tmp_path):
    scene = _scene(tmp_path, f'want = ["sensitivity", "report"]\ndir = "{tmp_path / "out"}"\n')
    row = _report_row(_cli("run", str(scene), "--explain", "--json", "--cache-dir", str(tmp_path / "c")))
    assert row["action"] == "run"
    assert f"builders: bridge + the scene summary, into {tmp_path / 'out'}" in row["reason"]
    assert "flexure (the scene computes no flexure)" in row["reason"]
    assert "calibration (the scene computes no calibration)" in row["reason"]
    assert "stability (not about one scene)" in row["reason"]
    assert not (tmp_path / "out").exists()          # --explain runs nothing


def test_default_directory_is_out_scene_name_never_the_shipped_reports(tmp_path):
    scene = _scene(tmp_path, 'want = ["sensitivity", "report"]\n')
    row = _report_row(_cli("run", str(scene), "--explain", "--json", "--cache-dir", str(tmp_path / "c")))
    assert "into out/rep_scene" in row["reason"]
    bad = _scene(tmp_path, f'want = ["report"]\ndir = "{ROOT / "reports"}"\n')
    r = _cli("run", str(bad), "--explain")
    assert r.returncode == 2 and r.stderr.count("\n") == 1, r.stderr
    assert "outputs.dir:" in r.stderr and "regenerate_shipped" in r.stderr
    ok = _scene(tmp_path, 'want = ["report"]\nregenerate_shipped = true\n')
    row = _report_row(_cli("run", str(ok), "--explain", "--json", "--cache-dir", str(tmp_path / "c")))
    assert f"into {(ROOT / 'reports').resolve()}" in row["reason"]


def test_a_listed_report_the_scene_cannot_feed_and_report_keys_without_report_are_refused(tmp_path):
    for outputs, field, text in [
        ('want = ["report"]\nreports = ["calibration"]\n', "outputs.reports",
         "'calibration' needs calibration"),
        ('want = ["report"]\nreports = ["stability"]\n', "outputs.reports", "not about one scene"),
        ('want = ["report"]\nreports = ["bridg"]\n', "outputs.reports", "did you mean 'bridge'"),
        ('want = ["sensitivity"]\ndir = "x"\n', "outputs.dir", 'outputs.want has no "report"'),
    ]:
        r = _cli("run", str(_scene(tmp_path, outputs)), "--explain")
        assert r.returncode == 2 and r.stderr.count("\n") == 1, r.stderr
        assert f"{field}:" in r.stderr and text in r.stderr, r.stderr


def test_report_stage_writes_the_chosen_builder_and_the_summary_into_the_scene_directory(tmp_path):
    shipped = ROOT / "reports" / "bridge.md"
    before = shipped.stat().st_mtime_ns
    out = tmp_path / "out"
    scene = _scene(tmp_path, f'want = ["report"]\nreports = ["bridge"]\ndir = "{out}"\n')
    r = _cli("run", str(scene), "--json", "--cache-dir", str(tmp_path / "c"))
    assert r.returncode == 0, r.stderr
    rep = json.loads(r.stdout)["report"]
    assert rep["areas"] == ["bridge"] and (out / "bridge.md").is_file()
    summary = (out / "rep_scene.md").read_text()
    assert "strain per N·m: 5e-05" in summary and "torque noise σ_τ" in summary
    assert shipped.stat().st_mtime_ns == before       # the shipped report was not touched
