"""`torquebench estimate`: outputs, --json, and bad input (exit 2, one line naming file/line/column)."""

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from estimator.log import log_to_frame, write_log
from estimator.log_reader import read_log
from estimator.robot import paper_leg
from estimator.synthetic import inverse_dynamics_log
from torquebench.cli import main

LEG_POKE = Path(__file__).resolve().parents[1] / "examples" / "leg_poke" / "leg_poke.csv"


@pytest.fixture(scope="module")
def good_log(tmp_path_factory):
    """A short static poke on link 1 (α = 0.3) from t = 0.1 s, floating base, 1 kHz."""
    robot = paper_leg()
    t = np.arange(300) * 1e-3
    q = np.tile([0.0, 0.0, 0.0, 0.8, -1.2], (300, 1))
    z = np.zeros_like(q)
    log, _ = inverse_dynamics_log(robot, t, q, z, z, 1, 0.3, [2.0, 1.0], active=t >= 0.1)
    path = tmp_path_factory.mktemp("logs") / "poke.csv"
    write_log(log, path)
    return path


def run(capsys, *argv):
    try:
        code = main(["estimate", *map(str, argv)])
    except SystemExit as exc:        # argparse errors
        code = exc.code
    out, err = capsys.readouterr()
    return code, out, err


def _bad(capsys, path, *extra):
    code, out, err = run(capsys, path, *extra)
    assert code == 2, (out, err)
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err
    return err


def test_csv_and_json(capsys, tmp_path, good_log):
    out_csv = tmp_path / "est.csv"
    code, out, err = run(capsys, good_log, "--out", out_csv, "--json")
    assert code == 0, err
    summary = json.loads(out)
    assert summary["samples"] == 300 and summary["skipped_samples"] == 0
    (iv,) = summary["intervals"]
    # the episode estimate (a grid-interpolated maximum likelihood): within 2 % of its stated 1σ
    assert iv["link"] == 1 and abs(iv["alpha"] - 0.3) < 0.02 * iv["alpha_error_estimate"]
    assert iv["alpha_error_estimate"] < 2e-3 and iv["position_bound_m"] > 0
    frame = pd.read_csv(out_csv)
    assert list(frame.columns) == ["t", "contact", "link", "alpha", "Fx", "Fz", "px", "pz", "rnorm"]
    assert len(frame) == 300
    assert (frame.contact[frame.t < 0.1] == 0).all() and frame.alpha[frame.t < 0.1].isna().all()
    late = frame[frame.t > 0.25]                # step transient 2.2 N · e^{-K·0.15 s} < 1e-6 N
    assert (late.link == 1).all()
    np.testing.assert_allclose(late[["Fx", "Fz"]], np.tile([2.0, 1.0], (len(late), 1)), atol=1e-6)
    assert not list(tmp_path.glob(".est.csv*"))          # no temp file left behind


def test_text_output_and_paper_method(capsys, good_log):
    code, out, _ = run(capsys, good_log, "--method", "paper", "--gain", "50", "--threshold", "0.1")
    assert code == 0 and "link 1" in out and "alpha 0.300" in out


def test_fixed_base_log(capsys, tmp_path):
    """No x, z, theta columns: base held at zero, the FT wrench still enters on the base rows."""
    robot = paper_leg(False)
    t = np.arange(200) * 1e-3
    q = np.tile([0.0, 0.0, 0.0, -0.5, 1.0], (200, 1))
    z = np.zeros_like(q)
    log, _ = inverse_dynamics_log(robot, t, q, z, z, 2, 0.7, [-1.5, 2.0])
    assert list(log_to_frame(log).columns)[:4] == ["t", "q1", "q2", "dq1"]
    path = tmp_path / "fixed.csv"
    write_log(log, path)
    code, out, _ = run(capsys, path, "--json")
    (iv,) = json.loads(out)["intervals"]
    assert code == 0 and iv["link"] == 2 and abs(iv["alpha"] - 0.7) < 1e-3


def test_nan_rows_are_skipped_and_counted(capsys, tmp_path, good_log):
    lines = good_log.read_text().splitlines()
    lines[51] = ",".join(["nan" if i == 13 else v for i, v in enumerate(lines[51].split(","))])
    lines[52] = ",".join(["inf" if i == 12 else v for i, v in enumerate(lines[52].split(","))])
    bad = tmp_path / "nan.csv"
    bad.write_text("\n".join(lines) + "\n")
    log = read_log(bad)
    assert log.n_skipped == 2 and log.skipped_lines.tolist() == [52, 53]
    assert log.valid_mask.sum() == 298 and np.all(np.isfinite(log.q))
    code, out, _ = run(capsys, bad, "--json")
    summary = json.loads(out)
    assert code == 0 and summary["samples"] == 298 and summary["skipped_samples"] == 2
    assert summary["skipped_lines"] == [52, 53]
    assert summary["intervals"][0]["link"] == 1


def _edit(tmp_path, src, name, fn):
    frame = pd.read_csv(src)
    frame = fn(frame)
    path = tmp_path / name
    frame.to_csv(path, index=False)
    return path


def test_misspelled_column(capsys, tmp_path, good_log):
    path = _edit(tmp_path, good_log, "typo.csv", lambda f: f.rename(columns={"tau2": "tua2"}))
    err = _bad(capsys, path)
    assert "typo.csv" in err and "'tau2'" in err and "tua2" in err


def test_missing_column(capsys, tmp_path, good_log):
    err = _bad(capsys, _edit(tmp_path, good_log, "miss.csv", lambda f: f.drop(columns=["My"])))
    assert "miss.csv" in err and "'My'" in err


def test_non_increasing_time(capsys, tmp_path, good_log):
    def swap(f):
        f.loc[10, "t"] = f.loc[9, "t"]
        return f
    err = _bad(capsys, _edit(tmp_path, good_log, "time.csv", swap))
    assert "time.csv" in err and "line 12" in err and "'t'" in err


def test_irregular_sampling(capsys, tmp_path, good_log):
    def jitter(f):
        f.loc[100:, "t"] += 0.0004
        return f
    err = _bad(capsys, _edit(tmp_path, good_log, "jit.csv", jitter))
    assert "jit.csv" in err and "line 102" in err and "irregular" in err


def test_non_numeric_field(capsys, tmp_path, good_log):
    def text(f):
        f["q1"] = f["q1"].astype(object)
        f.loc[5, "q1"] = "abc"
        return f
    err = _bad(capsys, _edit(tmp_path, good_log, "txt.csv", text))
    assert "line 7" in err and "'q1'" in err


def test_log_with_more_joints_than_the_robot(capsys, tmp_path, good_log):
    def third(f):
        for c in ("q3", "dq3", "tau3"):
            f[c] = 0.0
        return f
    err = _bad(capsys, _edit(tmp_path, good_log, "three.csv", third))
    assert "three.csv" in err and "3 joint" in err and "2 links" in err


def test_bad_robot_file(capsys, tmp_path, good_log):
    robot = tmp_path / "neg.toml"
    text = Path(paper_leg.__globals__["PAPER_LEG_TOML"]).read_text().replace("mass_kg = 0.351",
                                                                           "mass_kg = -0.351")
    robot.write_text(text)
    err = _bad(capsys, good_log, "--robot", robot)
    assert "neg.toml" in err and "mass_kg" in err


def test_missing_file_empty_file_and_bad_options(capsys, tmp_path, good_log):
    assert "nope.csv" in _bad(capsys, tmp_path / "nope.csv")
    empty = tmp_path / "empty.csv"
    empty.write_text("")
    assert "empty.csv" in _bad(capsys, empty)
    assert "--gain" in _bad(capsys, good_log, "--gain", "-3")
    assert "--method" in _bad(capsys, good_log, "--method", "magic")


def test_never_overwrites_the_input(capsys, tmp_path, good_log):
    copy = tmp_path / "in.csv"
    copy.write_bytes(good_log.read_bytes())
    before = copy.read_bytes()
    assert "refusing" in _bad(capsys, copy, "--out", copy)
    assert copy.read_bytes() == before


def test_leg_poke_summary(capsys):
    code, out, _ = run(capsys, LEG_POKE, "--json")
    (iv,) = json.loads(out)["intervals"]
    assert code == 0 and iv["link"] == 2 and abs(iv["alpha"] - 0.4) < 1e-3


def test_timing_option_side_file_and_bad_value(capsys, tmp_path, good_log):
    import shutil

    code, out, _ = run(capsys, good_log, "--json")
    assert code == 0 and json.loads(out)["timing_source"] == "default (instantaneous)"
    log = tmp_path / "declared.csv"
    shutil.copy(good_log, log)
    (tmp_path / "declared.timing.toml").write_text('[timing]\ndefault = "mean"\n')
    code, out, _ = run(capsys, log, "--json")
    s = json.loads(out)
    assert code == 0 and s["timing"] == "mean" and s["timing_source"] == "log declaration"
    code, out, _ = run(capsys, log, "--timing", "delay:0.001")
    assert code == 0 and "sensor timing: delay:0.001 (option)" in out
    err = _bad(capsys, good_log, "--timing", "sometimes")
    assert "--timing" in err
    (tmp_path / "declared.timing.toml").write_text('[timing]\nFy = "mean"\n')
    err = _bad(capsys, log)
    assert "timing.Fy" in err


def test_dynamic_default_is_the_chi_square_detector(capsys, good_log):
    code, out, _ = run(capsys, good_log, "--json")
    s = json.loads(out)
    assert code == 0 and s["detector"].startswith("chi-square")
    assert s["false_alarm_rate_per_s"] == pytest.approx(1 / 3600)
    assert "paper leg" in s["residual_noise_source"]
    assert s["intervals"] and s["intervals"][0]["link"] == 1
    code, out, _ = run(capsys, good_log, "--json", "--threshold", "0.06")
    assert json.loads(out)["detector"].startswith("paper rule")


def test_noise_side_file_is_read_and_options_override_it(capsys, tmp_path, good_log):
    """LOG.noise.toml beside the log states the sensors' noise; the --*-sigma options and
    --quiet-window take precedence; a bad declaration is one line naming its file and field."""
    import shutil

    log = tmp_path / "declared.csv"
    shutil.copy(good_log, log)
    side = tmp_path / "declared.noise.toml"
    side.write_text("[noise]\ntorque_sigma_Nm = [0.02, 0.03]\nft_sigma = [0.2, 0.2, 0.02]\n")
    code, out, _ = run(capsys, log, "--json")
    s = json.loads(out)
    assert code == 0 and "log declaration declared.noise.toml" in s["residual_noise_source"]
    assert "[0.02, 0.03]" in s["residual_noise_source"] and "[0.2, 0.2, 0.02]" in s["residual_noise_source"]
    code, out, _ = run(capsys, log, "--json", "--torque-sigma", "0.01")
    assert code == 0 and "--torque-sigma" in json.loads(out)["residual_noise_source"]
    for text, field in [("[noise]\ntorque_sigma_Nm = [0.0]\nft_sigma = [0.1, 0.1, 0.01]\n", "noise.torque_sigma_Nm"),
                        ("[noise]\ntorque_sigma_Nm = [0.01]\nft_sigma = [0.1, 0.1]\n", "noise.ft_sigma"),
                        ("[noise]\ntorque_sigma_Nm = [0.01]\nft_sigma = [0.1, 0.1, 0.01]\nft_sgma = 1\n", "noise.ft_sgma"),
                        ("[noise]\nft_sigma = [0.1, 0.1, 0.01]\n", "noise.torque_sigma_Nm"),
                        ("[noise]\ntorque_sigma_Nm = [0.01, 0.01, 0.01]\nft_sigma = [0.1, 0.1, 0.01]\n",
                         "noise.torque_sigma_Nm")]:
        side.write_text(text)
        err = _bad(capsys, log)
        assert "declared.noise.toml" in err and field in err, err


@pytest.mark.parametrize("option,value,name", [
    ("--torque-sigma", "0", "torque sigma"), ("--ft-sigma", "0.1,-0.1,0.01", "FT sigma"),
    ("--false-alarm-rate", "1/sample", "--false-alarm-rate"),
    ("--false-alarm-rate", "5000/s", "--false-alarm-rate"),
    ("--quiet-window", "0.05:0.25", "--quiet-window"), ("--quiet-window", "abc", "--quiet-window")])
def test_bad_detector_options_exit_2(capsys, good_log, option, value, name):
    err = _bad(capsys, good_log, option, value)
    assert name in err


def test_parquet_log_and_output_match_csv(capsys, tmp_path, good_log):
    pytest.importorskip("pyarrow")
    log = read_log(good_log)
    pq = tmp_path / "poke.parquet"
    write_log(log, pq)
    back = read_log(pq)
    assert np.array_equal(back.q, log.q) and np.array_equal(back.tau_meas, log.tau_meas)
    assert run(capsys, good_log, "--out", tmp_path / "a.csv")[0] == 0
    assert run(capsys, pq, "--out", tmp_path / "b.parquet")[0] == 0
    a = pd.read_csv(tmp_path / "a.csv")
    b = pd.read_parquet(tmp_path / "b.parquet")
    assert list(a.columns) == list(b.columns)
    assert np.array_equal(a["contact"], b["contact"])
    assert np.allclose(a["Fx"].fillna(0), b["Fx"].fillna(0), rtol=1e-8, atol=0)
    (tmp_path / "junk.parquet").write_text("not parquet")
    assert "Parquet" in _bad(capsys, tmp_path / "junk.parquet")
