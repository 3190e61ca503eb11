"""`propagate --calibration`: σ_τ comes from the calibration's own reading noise through its slope
(not from the paper's bridge chain), the output says so, and a calibration that disagrees with the
sensor chain by more than 2× is warned about."""

import json
from types import SimpleNamespace

import numpy as np

from torquebench.io import REPO_ROOT

CAL = REPO_ROOT / "calibration" / "data" / "paper_link1_cal.json"


def test_sigma_tau_is_the_calibrations_reading_noise(tmp_path, cli_inprocess):
    doc = json.loads(CAL.read_text())
    expected = (doc["posterior"]["sigma"]["mean"] / abs(doc["coefficients"]["slope"])
                * 1e-3 * 9.81 * doc["lever_arm_m"])          # calibration.session: g = 9.81
    proc = cli_inprocess("propagate", "--calibration", CAL, "--grid", "2", "--draws", "20", "--json",
                         cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    out = json.loads(proc.stdout)
    assert abs(out["torque_noise_std_Nm"] - expected) < 1e-9 * expected
    assert "calibration's reading noise" in out["torque_noise_source"]
    assert out["warnings"] == []                    # the paper's chain and this calibration agree


def test_a_calibration_far_from_the_chain_is_warned_about():
    from torquebench.pipeline import calibration_noise

    cal = SimpleNamespace(coef_names=("slope", "offset"), coef_mean=np.array([0.0115, 5.0]),
                          sigma=1.21, reading_unit="mV", source="cal.json", lever_arm_m=0.205,
                          _torque_per_g=lambda: 1e-3 * 9.80665 * 0.205)
    chain = SimpleNamespace(noise_std_Nm=0.0133, counts_per_Nm=1e5)
    sigma, source, warnings = calibration_noise(cal, chain)
    assert abs(sigma - 1.21 / 0.0115 * 1e-3 * 9.80665 * 0.205) < 1e-12
    assert len(warnings) == 1 and "16× the sensor chain's" in warnings[0]


def test_posture_is_refused_for_a_planar_robot(tmp_path, cli_inprocess):
    """--posture is the URDF map's; a planar robot's map is a grid, so the option is refused, not ignored."""
    proc = cli_inprocess("propagate", "--posture", "0.1,0.2", cwd=tmp_path)
    assert proc.returncode == 2 and "--posture: for URDF robots" in proc.stderr
