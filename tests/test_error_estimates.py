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
