"""`report` as a stage: a scene asks for reports in [outputs]; the report is a view of the scene's own
results (torquebench.scene_views): only the views of what the scene computes are drawn, into the
scene's output directory, never the shipped reports/ unless asked, and nothing in it comes from
another scene or a shipped file."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

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


@pytest.fixture
def _cli(cli_inprocess):
    """``torquebench ARGS`` in-process (from ``cwd``, default the repository root): these check
    what the command answers, not the process; an interpreter start-up and import less per call."""
    return lambda *args, cwd=ROOT: cli_inprocess(*args, cwd=cwd)


def _report_row(r):
    assert r.returncode == 0, r.stderr
    return next(s for s in json.loads(r.stdout)["stages"] if s["stage"] == "report")


def test_explain_lists_only_the_views_whose_inputs_the_scene_has(tmp_path, _cli):
    scene = _scene(tmp_path, f'want = ["sensitivity", "report"]\ndir = "{tmp_path / "out"}"\n')
    row = _report_row(_cli("run", str(scene), "--explain", "--json", "--cache-dir", str(tmp_path / "c")))
    assert row["action"] == "run"
    assert f"views: bridge + the scene summary, into {tmp_path / 'out'}" in row["reason"]
    assert "estimator (the scene computes no estimates)" in row["reason"]
    assert "flexure (the scene computes no flexure)" in row["reason"]
    assert "calibration (the scene computes no calibration)" in row["reason"]
    assert "stability (not about one scene)" in row["reason"]
    assert not (tmp_path / "out").exists()          # --explain runs nothing


def test_default_directory_is_out_scene_name_never_the_shipped_reports(tmp_path, _cli):
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


def test_a_listed_report_the_scene_cannot_feed_and_report_keys_without_report_are_refused(tmp_path, _cli):
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


def test_report_stage_writes_the_chosen_view_and_the_summary_into_the_scene_directory(tmp_path, _cli):
    shipped = ROOT / "reports" / "bridge.md"
    before = shipped.stat().st_mtime_ns
    out = tmp_path / "out"
    scene = _scene(tmp_path, f'want = ["report"]\nreports = ["bridge"]\ndir = "{out}"\n')
    r = _cli("run", str(scene), "--json", "--cache-dir", str(tmp_path / "c"))
    assert r.returncode == 0, r.stderr
    rep = json.loads(r.stdout)["report"]
    assert rep["areas"] == ["bridge"] and (out / "bridge_noise_budget.png").is_file()
    assert not (out / "bridge.md").exists()           # the shipped builder's report is not drawn
    summary = (out / "rep_scene.md").read_text()
    assert "strain per N·m: 5e-05" in summary and "torque noise σ_τ" in summary
    assert "## Sensor chain" in summary and "![noise budget](bridge_noise_budget.png)" in summary
    assert shipped.stat().st_mtime_ns == before       # the shipped report was not touched


def _own_files(d: Path) -> set[str]:
    return {p.name for p in d.iterdir() if not p.name.startswith(".")}


def test_a_scene_with_its_own_sensor_gets_only_views_of_its_own_results(tmp_path, _cli):
    """Every file in the scene's report folder is derived from this scene: its own sensor (a
    20-bit ADC at 1 kS/s, not the paper's), no shipped report (bridge.md / bridge.png of the paper's
    sensor, the leg-poke plot of examples/), and the summary's figures are this sensor's."""
    from bridge.chain import SensorChain
    from bridge.config import load_sensor_config

    sensor = tmp_path / "my_sensor.toml"
    sensor.write_text((ROOT / "sensors" / "paper_sensor.toml").read_text()
                      .replace("bits = 24", "bits = 20").replace("enob = 16.0", "enob = 14.5")
                      .replace("data_rate_Hz = 4000.0", "data_rate_Hz = 1000.0"))
    out = tmp_path / "out"
    scene = tmp_path / "scene.toml"
    scene.write_text(STATIC + f'[sensor]\nfile = "{sensor}"\n[outputs]\nwant = ["sensitivity", "report"]\ndir = "{out}"\n')
    r = _cli("run", str(scene), "--json", "--cache-dir", str(tmp_path / "c"))
    assert r.returncode == 0, r.stderr
    assert json.loads(r.stdout)["report"]["areas"] == ["bridge"]
    assert _own_files(out) == {"rep_scene.md", "bridge_noise_budget.png"}
    chain = SensorChain(load_sensor_config(sensor)[0], 5e-5)
    summary = (out / "rep_scene.md").read_text()
    assert f"torque noise σ_τ: {chain.noise_std_Nm:.4g} N·m" in summary
    assert "20 bits, 1000 S/s, ENOB 14.5" in summary and "my_sensor.toml" in summary
    paper = SensorChain(load_sensor_config(ROOT / "sensors" / "paper_sensor.toml")[0], 5e-5)
    assert f"{paper.noise_std_Nm:.4g} N·m" not in summary


def _leg_estimates():
    """Both methods on a short leg log (inverse dynamics, 5 N on link 2 from 0.3 s) with the
    chi-square detector, and the true contact flags."""
    from estimator.noise import NoiseModel
    from estimator.estimate import estimate
    from estimator.robot import paper_leg
    from estimator.synthetic import moving_leg_poke

    robot = paper_leg()
    log, truth = moving_leg_poke(robot, duration_s=0.6, t_on_s=0.3)
    rng = np.random.default_rng(0)
    log.tau_Nm = log.tau_Nm + 0.01 * rng.standard_normal(log.tau_Nm.shape)
    log.wrench = log.wrench + np.array([0.1, 0.1, 0.01]) * rng.standard_normal(log.wrench.shape)
    noise = NoiseModel(torque_sigma_Nm=[0.01], ft_sigma=[0.1, 0.1, 0.01])
    ests = {m: estimate(robot, log, method=m, noise=noise) for m in ("dynamic", "paper")}
    return robot, ests, log.t >= 0.3


def test_residual_plot_keeps_units_on_separate_axes():
    """‖r‖ (whitened, dimensionless) never shares an axis with the residual's rows; the force rows
    (N) and the moment/torque rows (N·m) each have their own axis, carrying exactly those rows."""
    from torquebench.scene_views import residual_figure, residual_rows

    robot, ests, on = _leg_estimates()
    est = ests["dynamic"]
    assert residual_rows(robot) == [("base x", "N"), ("base z", "N"), ("base θ", "N·m"),
                                    ("joint q1", "N·m"), ("joint q2", "N·m")]
    fig = residual_figure(est, robot, on, methods=ests)
    labels = [a.get_ylabel() for a in fig.axes]
    assert len(labels) == 4, labels            # chi-square statistic, paper ‖r‖, N rows, N·m rows
    assert "dimensionless" in labels[0] and "N" not in labels[0].replace("(dimensionless)", "")
    assert "paper rule" in labels[1]
    assert labels[2].endswith("(N)") and labels[3].endswith("(N·m)")
    lines = {a.get_ylabel(): {ln.get_label(): ln for ln in a.get_lines() if not ln.get_label().startswith("_")}
             for a in fig.axes}
    assert set(lines[labels[2]]) == {"r base x", "r base z"}
    assert set(lines[labels[3]]) == {"r base θ", "r joint q1", "r joint q2"}
    np.testing.assert_array_equal(lines[labels[2]]["r base z"].get_ydata(), est.residual[:, 1])
    np.testing.assert_array_equal(lines[labels[0]]["dynamic"].get_ydata(), est.rnorm)
    thr = [ln for ln in fig.axes[0].get_lines() if ln.get_label().startswith("√χ²")]
    assert len(thr) == 1 and thr[0].get_ydata()[0] == pytest.approx(np.sqrt(est.info["chi2_threshold"]))
    # the residual's scale is on its own axis: the statistic's range does not stretch the rows' axis
    n_ax = fig.axes[2].get_ylim()
    assert max(abs(v) for v in n_ax) < 2 * np.abs(est.residual[:, :2]).max() + 1e-9
    import matplotlib.pyplot as plt

    plt.close(fig)


@pytest.mark.slow
def test_a_dynamic_scenes_report_holds_its_estimate_residual_and_scores_only(tmp_path, _cli):
    """A short floating-leg scene with want = ["report"]: the folder holds the views of its sensor
    chain, estimate and residual (no shipped report, no leg-poke plot of examples/)."""
    text = (ROOT / "scenes" / "paper_floating_link2.toml").read_text()
    out = tmp_path / "out"
    scene = tmp_path / "dyn.toml"
    scene.write_text(text + f'\n[outputs]\nwant = ["report"]\nreports = ["bridge", "estimator", "detection"]\n'
                       f'dir = "{out}"\n')
    r = _cli("run", str(scene), "--json", "--cache-dir", str(tmp_path / "c"))
    assert r.returncode == 0, r.stderr
    assert _own_files(out) == {"paper_floating_link2.md", "bridge_noise_budget.png",
                               "estimator_vs_truth.png", "detection_residual.png"}
    summary = (out / "paper_floating_link2.md").read_text()
    assert "![residual](detection_residual.png)" in summary and "## Detection" in summary


def test_views_draw_only_from_the_artifacts_they_are_given(tmp_path):
    """The calibration view plots the scene's own session and fit (mass in g against the reading
    in the calibration's unit); the estimator view plots the given estimates against the given
    truth; both write only into the directory they are given."""
    from types import SimpleNamespace

    import matplotlib.pyplot as plt

    from calibration.model import SensorModel
    from calibration.session import Session
    from torquebench import scene_views as V

    mass = np.tile([0.0, 100.0, 500.0, 1000.0], 2)
    reading = 40.0 * mass + 7.0 + np.random.default_rng(1).normal(0, 3.0, mass.size)
    session = Session(mass_g=mass, reading=reading, direction=np.array(["load"] * mass.size),
                      repeat=np.repeat([0, 1], 4), timestamp_s=np.full(mass.size, np.nan),
                      lever_arm_m=0.2, reading_unit="counts")
    cal = SensorModel(model="linear", coef_names=("slope", "offset"), coef_mean=np.array([40.0, 7.0]),
                      coef_cov=np.diag([1e-4, 1.0]), sigma=3.0, samples=np.zeros((4, 2)),
                      sigma_samples=np.ones(4), lever_arm_m=0.2, reading_unit="counts")
    fig = V.calibration_figure(session, cal)
    assert [a.get_ylabel() for a in fig.axes] == ["mass (g)", "mass − fit (g)"]
    assert fig.axes[1].get_xlabel() == "reading (counts)"
    np.testing.assert_allclose(fig.axes[0].get_lines()[0].get_xdata(), reading)
    plt.close(fig)
    scene = SimpleNamespace(name="s", chain=SimpleNamespace(calibration_file=None))
    lines, paths = V.VIEWS["calibration"].draw(scene, {"calibration": cal, "session": session}, tmp_path)
    assert [p.name for p in paths] == ["calibration_fit.png"] and "![calibration fit](calibration_fit.png)" in lines
    assert "slope 40 ± 0.01 counts/g" in "\n".join(lines)

    robot, ests, on = _leg_estimates()
    truth = {"link": np.where(on, 2, 0), "alpha": np.full(on.size, 0.5), "Fx": np.where(on, 2.5, 0.0),
             "Fz": np.where(on, -4.3, 0.0)}
    fig = V.estimate_figure(ests, truth)
    assert [a.get_ylabel() for a in fig.axes] == ["contact (0/1)", "link", "α (along the link, 0–1)",
                                                  "F on the robot (N)"]
    labels = {ln.get_label() for ln in fig.axes[3].get_lines()}
    assert {"Fx dynamic", "Fz paper", "truth Fx", "truth Fz"} <= labels
    plt.close(fig)
    assert {p.name for p in tmp_path.iterdir() if not p.name.startswith(".")} == {"calibration_fit.png"}
