"""Error estimates on command answers (convention: X_error_estimate + X_error_method beside X)."""

import json

import numpy as np

from bridge.budget import noise_budget, sensor_summary
from bridge.config import SensorConfig
from torquebench.cli import main


def test_bridge_error_estimate_is_the_enob_definition_spread(capsys):
    cfg = SensorConfig()
    out = sensor_summary(cfg, 5.718e-4)
    other = "ieee" if cfg.enob_definition == "ti" else "ti"
    from dataclasses import replace
    alt = noise_budget(replace(cfg, enob_definition=other), 5.718e-4).total_Nm
    assert np.isclose(out["min_detectable_torque_Nm_error_estimate"], abs(alt - out["min_detectable_torque_Nm"]))
    assert "ENOB-definition" in out["min_detectable_torque_Nm_error_method"]
    assert main(["bridge", "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    assert d["min_detectable_torque_Nm_error_estimate"] > 0


def test_apply_json_carries_per_sample_error(capsys, tmp_path):
    from torquebench.io import REPO_ROOT

    cal = REPO_ROOT / "calibration" / "data" / "paper_link1_cal.json"
    readings = REPO_ROOT / "calibration" / "data" / "paper_link1_readings.csv"
    assert main(["apply", str(cal), str(readings), "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    assert np.allclose(d["mass_g_error_estimate"], d["mass_std_g"])
    assert np.all(np.asarray(d["mass_g_error_estimate"], float) > 0)
    assert "posterior" in d["mass_g_error_method"]


def test_simulate_json_error_estimate_and_tolerance_warning(capsys, tmp_path):
    base = ["simulate", "scenes/moving_leg.toml", "--duration", "0.05", "--json"]
    assert main(base + ["--out", str(tmp_path / "a.csv"), "--error-tolerance", "1e-15"]) == 0
    d = json.loads(capsys.readouterr().out)
    assert 0 < d["q_rad_error_estimate"] < 1e-4 and "tighter" in d["q_rad_error_method"]
    assert len(d["warnings"]) == 1 and "exceeds --error-tolerance" in d["warnings"][0]
    assert main(base + ["--out", str(tmp_path / "b.csv"), "--error-tolerance", "1"]) == 0
    assert "warnings" not in json.loads(capsys.readouterr().out)
    assert main(base + ["--out", str(tmp_path / "c.csv"), "--error-tolerance", "-1"]) == 2
    assert "--error-tolerance" in capsys.readouterr().err
