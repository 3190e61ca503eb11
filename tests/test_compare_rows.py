"""`compare`: each row carries the design's figures with their ± (sensitivity, stiffness, safety
factor, minimum detectable torque) and the largest cross-talk, beside noise and localization error;
the plot draws them with error bars."""

import matplotlib

matplotlib.use("Agg")

from torquebench.commands import compare as C  # noqa: E402

FX = {"sensitivity_mV_per_V_per_Nm": 0.115, "sensitivity_mV_per_V_per_Nm_error_estimate": 1.3e-4,
      "sensitivity_mV_per_V_per_Nm_error_method": "levels",
      "torsional_stiffness_Nm_per_rad": 1712.0, "torsional_stiffness_Nm_per_rad_error_estimate": 10.0,
      "torsional_stiffness_Nm_per_rad_error_method": "levels",
      "safety_factor": 4.3, "safety_factor_error_estimate": 0.05, "safety_factor_error_method": "levels",
      "min_detectable_torque_Nm": 0.0133, "min_detectable_torque_Nm_error_estimate": 1.5e-5,
      "min_detectable_torque_Nm_error_method": "strain", "crosstalk_max_percent": 0.018}


def _point(name):
    return {"point": {"flexure": name},
            "result": {"flexure": FX, "sensor": {"sensitivity_V_per_Nm": 1e-4, "torque_noise_std_Nm": 0.0133},
                       "predicted": {"dynamic": {"position_rms_m": 1e-3, "position_rms_m_error_estimate": 2e-5}},
                       "measured": {"dynamic": {"position_error_rms_m": 1.1e-3}}}}


def test_rows_carry_the_design_figures_with_their_error(tmp_path, capsys):
    rows = [C.row(_point("a.toml")), C.row(_point("b.toml")), C.row({"point": {"flexure": "c"}, "error": "x"})]
    for key in C.DESIGN_FIGURES:
        assert rows[0][key] == FX[key] and rows[0][f"{key}_error_estimate"] == FX[f"{key}_error_estimate"]
    assert rows[0]["crosstalk_max_percent"] == 0.018
    C._plot(tmp_path / "c.png", rows)
    assert (tmp_path / "c.png").stat().st_size > 10_000
