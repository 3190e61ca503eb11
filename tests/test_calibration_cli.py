"""CLI: calibrate / apply / acquire contracts (JSON keys, exit 2 with one line, no overwrite)."""

import io
import json
import subprocess
import sys

import numpy as np
import pytest

from pty_device import pty_device
from torquebench.cli import main
from torquebench.io import REPO_ROOT

DATA = REPO_ROOT / "calibration" / "data" / "paper_link1_session.csv"


@pytest.fixture
def run(cli_inprocess):
    """The CLI's main in-process: these check the commands' contract, not the process."""
    return cli_inprocess


def test_calibrate_json_versioning_force_and_apply(tmp_path, run):
    out = tmp_path / "cal.json"
    p = run("calibrate", str(DATA), "--out", str(out), "--json")
    assert p.returncode == 0, p.stderr
    res = json.loads(p.stdout)
    for key in ("slope_mV_per_g", "offset_mV", "slope_mV_per_g_error_estimate",
                "offset_mV_error_estimate", "sigma_mV", "slope_mV_per_g_error_method", "r2",
                "autocorr_time", "acceptance_fraction", "converged", "sensitivity_mV_per_Nm"):
        assert key in res, key
    assert not {"slope", "offset", "sigma", "slope_std"} & set(res)      # every figure has its unit
    assert res["converged"] is True and not res["versioned"]
    assert abs(res["slope_mV_per_g"] - 0.0115) < 4 * res["slope_mV_per_g_error_estimate"]
    assert abs(res["offset_mV"] - 5.0069) < 4 * res["offset_mV_error_estimate"]
    # 1 g at 0.205 m is 2.01e-3 N·m: the sensitivity is the slope over that torque
    assert res["sensitivity_mV_per_Nm"] == pytest.approx(res["slope_mV_per_g"] / (1e-3 * 9.81 * 0.205))
    assert {p.split("/")[-1] for p in res["report"]} == {"cal.md", "cal_corner.png", "cal_residuals.png"}
    before = out.read_bytes()
    p2 = run("calibrate", str(DATA), "--out", str(out), "--json", "--no-report", "--seed", "1")
    res2 = json.loads(p2.stdout)
    assert p2.returncode == 0 and res2["versioned"] and res2["written"].endswith("cal.v2.json")
    assert out.read_bytes() == before
    p3 = run("calibrate", str(DATA), "--out", str(out), "--json", "--no-report", "--force")
    assert p3.returncode == 0 and json.loads(p3.stdout)["written"] == str(out)

    readings = tmp_path / "r.csv"
    readings.write_text("reading\n5.0069\n16.5069\n")
    p4 = run("apply", str(out), str(readings), "--json", "--data", str(DATA))
    assert p4.returncode == 0, p4.stderr
    r = json.loads(p4.stdout)
    assert np.allclose(r["torque_Nm"], [0, 1000 * 9.81e-3 * 0.205], atol=4 * max(r["torque_std_Nm"]))
    p5 = run("apply", str(out), str(readings), "--out", str(tmp_path / "t.csv"))
    assert p5.returncode == 0 and "torque_std_Nm" in (tmp_path / "t.csv").read_text()
    p6 = run("apply", str(out), str(readings), "--out", str(tmp_path / "t.csv"))
    assert p6.returncode == 2 and "exists" in p6.stderr


@pytest.mark.parametrize("content,args,match", [
    ("mass_g,reading\n10,1\n20,x\n", [], "line 3: column 'reading'"),
    (None, ["--max-steps", "120"], "unconverged"),
    (None, ["--model", "hysteresis"], "needs both 'load' and 'unload'"),
])
def test_calibrate_user_errors_exit_2_one_line(tmp_path, content, args, match, run):
    data = DATA
    if content is not None:
        data = tmp_path / "bad.csv"
        data.write_text(content)
    p = run("calibrate", str(data), "--out", str(tmp_path / "c.json"), *args)
    assert p.returncode == 2 and p.stdout == ""
    assert len(p.stderr.strip().splitlines()) == 1 and match in p.stderr, p.stderr
    assert not (tmp_path / "c.json").exists()


def test_apply_rejects_tampered_calibration(tmp_path, run):
    cal = tmp_path / "c.json"
    assert run("calibrate", str(DATA), "--out", str(cal), "--no-report").returncode == 0
    cal.write_text(cal.read_text().replace('"model": "linear"', '"model": "quadratic"'))
    (tmp_path / "r.csv").write_text("reading\n6\n")
    p = run("apply", str(cal), str(tmp_path / "r.csv"))
    assert p.returncode == 2 and "content hash mismatch" in p.stderr


@pytest.fixture
def device():
    with pty_device(12345.0) as tty:
        yield tty


def test_acquire_records_raw_and_decodes(device, tmp_path, capsys):
    rc = main(["acquire", "--port", device, "--out", str(tmp_path / "a.raw"), "--channels", "2",
               "--frames", "1000", "--csv", str(tmp_path / "a.csv"), "--json"])
    assert rc == 0
    res = json.loads(capsys.readouterr().out)
    assert res["frames"] >= 1000 and res["corrupted"] == 0 and res["lost"] == 0
    assert res["garbage_bytes"] > 0
    assert (tmp_path / "a.raw").stat().st_size == res["bytes"]
    rows = np.loadtxt(tmp_path / "a.csv", delimiter=",", skiprows=1)
    assert rows.shape[1] == 3 and abs(rows[:, 1].mean() - 12345) < 5


def test_acquire_guided_writes_a_loadable_session(device, tmp_path, capsys, monkeypatch):
    from calibration.session import read_session
    monkeypatch.setattr(sys, "stdin", io.StringIO("\n\n\n"))
    rc = main(["acquire", "--port", device, "--out", str(tmp_path / "g.raw"), "--channels", "2",
               "--guided", "0,50,100", "--rate-hz", "2000", "--settle-s", "0.05",
               "--window-s", "0.2", "--lever-arm-m", "0.205", "--sensor-id", "j1", "--json"])
    assert rc == 0
    res = json.loads(capsys.readouterr().out)
    assert res["readings"] == 3
    s = read_session(tmp_path / "g.csv")
    assert s.reading_unit == "counts" and s.sensor_id == "j1" and list(s.mass_g) == [0, 50, 100]
    assert np.all(np.abs(s.reading - 12345) < 5)


def test_acquire_bad_port_exit_2(tmp_path, run):
    p = run("acquire", "--port", str(tmp_path / "nope"), "--out", str(tmp_path / "x.raw"))
    assert p.returncode == 2 and len(p.stderr.strip().splitlines()) == 1 and "--port" in p.stderr


def test_apply_bad_reading_names_the_file_line(tmp_path, run):
    cal = REPO_ROOT / "calibration" / "data" / "paper_link1_cal.json"
    (tmp_path / "r.csv").write_text("# reading_unit=mV\nreading\n6\nseven\n")
    p = run("apply", str(cal), str(tmp_path / "r.csv"))
    assert p.returncode == 2 and "line 4: column 'reading': 'seven'" in p.stderr, p.stderr


def test_apply_without_out_prints_a_summary_not_the_table(run):
    """Its help says: without --out, a summary only (the per-reading table is --out or --json)."""
    cal = REPO_ROOT / "calibration" / "data" / "paper_link1_cal.json"
    p = run("apply", str(cal), str(REPO_ROOT / "calibration" / "data" / "paper_link1_readings.csv"))
    assert p.returncode == 0, p.stderr
    lines = p.stdout.strip().splitlines()
    assert len(lines) <= 4 and lines[0].startswith("11 readings") and "N·m" in lines[1]
    assert "torque_std_Nm" not in p.stdout              # no CSV header
