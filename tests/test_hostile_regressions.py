"""Regression tests of the findings of the full hostile pass (benchmarks/hostile_pass.py, seed 1)
re-run after the schema merge: each case as the pass ran it, checked for the outcome now expected
(exit 2 and one line naming the file/field, or a warning, and no user file changed)."""

import shutil
from pathlib import Path

import pandas as pd
import pytest

from torquebench.cli import main

ROOT = Path(__file__).resolve().parents[1]


def _one_line_error(capsys, code):
    err = [ln for ln in capsys.readouterr().err.splitlines() if ln.strip()]
    assert code == 2 and len(err) == 1, err
    return err[0]


@pytest.mark.parametrize("src", ["sim/paper_floating_link1", "leg_poke/leg_poke"])
def test_joint_rates_in_deg_per_s_beside_a_base_in_si_are_refused(tmp_path, capsys, src):
    """A floating log whose joint rates are deg/s: the base's agreeing velocities no longer hide it
    (the velocity scale is checked per group, estimator.plausibility.Checker)."""
    d = pd.read_csv(ROOT / "examples" / f"{src}.csv")
    d[["dq1", "dq2"]] *= 57.29577951308232
    d.to_csv(tmp_path / "bad.csv", index=False)
    code = main(["estimate", str(tmp_path / "bad.csv")])
    line = _one_line_error(capsys, code)
    assert "bad.csv: joint velocities disagree" in line and "deg/s" in line


def test_a_clean_floating_log_passes_the_velocity_check(tmp_path, capsys):
    for suf in (".csv", ".timing.toml", ".noise.toml"):
        shutil.copy(ROOT / "examples" / "sim" / f"paper_floating_link1{suf}", tmp_path / f"ok{suf}")
    assert main(["estimate", str(tmp_path / "ok.csv")]) == 0
    assert "velocities disagree" not in capsys.readouterr().err
