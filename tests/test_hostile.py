"""Hostile input: each reported example ends with exit 2 and one line, or a flagged
answer; no input or earlier output is changed. The CLI runs in-process (``cli.main``)."""

import json
import shutil

import numpy as np
import pytest

from calibration.store import encode
from torquebench.cli import main
from torquebench.io import REPO_ROOT
from userio.errors import InputError
from userio.files import write_files_atomic
from userio.outputs import Outputs

DATA = REPO_ROOT / "calibration" / "data"
SCENES = REPO_ROOT / "scenes"


def cli(argv, capsys):
    """(exit code, stdout, stderr) of ``torquebench argv`` run in-process."""
    try:
        code = main([str(a) for a in argv])
    except SystemExit as exc:
        code = exc.code
    out, err = capsys.readouterr()
    return code, out, err


def assert_one_line_error(code, err, match=None):
    assert code == 2, err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in err, err
    if match:
        assert match in lines[0], lines[0]


@pytest.fixture()
def work(tmp_path):
    shutil.copy(DATA / "paper_link1_session.csv", tmp_path / "s.csv")
    shutil.copy(DATA / "paper_link1_cal.json", tmp_path / "cal.json")
    return tmp_path


def snapshot(d):
    return {p.name: p.read_bytes() for p in sorted(d.iterdir()) if p.is_file()}


# --------------------------------------------------------------------------- outputs vs inputs
@pytest.mark.parametrize("argv, match", [
    (["calibrate", "{d}/s.csv", "--out", "{d}/cal.md"], "two outputs would overwrite each other"),
    (["calibrate", "{d}/s.csv", "--out", "{d}/s.csv", "--force"], "refusing to overwrite an input"),
    (["apply", "{d}/cal.json", "{d}/s.csv", "--out", "{d}/cal.json", "--force"],
     "refusing to overwrite an input"),
    (["apply", "{d}/cal.json", "{d}/s.csv", "--out", "{d}/s.csv", "--force"],
     "refusing to overwrite an input"),
    (["simulate", str(SCENES / "paper_fixed_link1.toml"), "--out", "{d}/a.truth.csv",
      "--seed", "1"], None),
])
def test_outputs_never_clobber_inputs(work, capsys, argv, match):
    before = snapshot(work)
    argv = [a.replace("{d}", str(work)) for a in argv]
    if argv[0] == "simulate":                # a.truth.csv as the log: its truth is a.truth.truth.csv
        code, out, err = cli(argv, capsys)
        assert code == 0, err
        return
    code, out, err = cli(argv, capsys)
    assert_one_line_error(code, err, match)
    assert snapshot(work) == before


def test_simulate_out_is_a_hard_link_to_the_scene_is_refused(tmp_path, capsys):
    scene = tmp_path / "s.toml"
    shutil.copy(SCENES / "paper_fixed_link1.toml", scene)
    (tmp_path / "log.csv").hardlink_to(scene)
    before = scene.read_bytes()
    code, _, err = cli(["simulate", scene, "--out", tmp_path / "log.csv"], capsys)
    assert_one_line_error(code, err, "refusing to overwrite an input")
    assert scene.read_bytes() == before


def test_simulate_writes_log_and_truth_as_a_set(tmp_path, capsys):
    out = tmp_path / "a.csv"
    code, _, err = cli(["simulate", SCENES / "paper_fixed_link1.toml", "--out", out], capsys)
    assert code == 0, err
    assert out.exists() and (tmp_path / "a.truth.csv").exists()
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]     # no temp left


def test_write_files_atomic_is_all_or_nothing(tmp_path):
    a, b = tmp_path / "a.txt", tmp_path / "b.txt"
    a.write_text("old a")
    b.write_text("old b")

    def boom(tmp):
        raise RuntimeError("disk full")

    with pytest.raises(RuntimeError):
        write_files_atomic([(a, "new a"), (b, boom)])
    assert a.read_text() == "old a" and b.read_text() == "old b"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.txt", "b.txt"]
    write_files_atomic([(a, "new a"), (b, b"new b")])
    assert a.read_text() == "new a" and b.read_text() == "new b"
    with pytest.raises(InputError, match="exists"):
        write_files_atomic([(tmp_path / "c.txt", "c"), (a, "x")], overwrite=False)
    assert not (tmp_path / "c.txt").exists() and a.read_text() == "new a"


def test_write_files_atomic_restores_old_files_when_a_rename_fails(tmp_path, monkeypatch):
    import os

    a, b = tmp_path / "a.txt", tmp_path / "b.txt"
    a.write_text("old a")
    b.write_text("old b")
    real = os.replace
    calls = []

    def flaky(src, dst):
        calls.append(dst)
        if str(dst) == str(b) and len(calls) == 2:
            raise OSError("rename failed")
        return real(src, dst)

    monkeypatch.setattr(os, "replace", flaky)
    with pytest.raises(OSError):
        write_files_atomic([(a, "new a"), (b, "new b")])
    monkeypatch.setattr(os, "replace", real)
    assert a.read_text() == "old a" and b.read_text() == "old b"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.txt", "b.txt"]


def test_plan_outputs_refuses_collisions_and_symlinked_inputs(tmp_path):
    inp = tmp_path / "in.csv"
    inp.write_text("x")
    (tmp_path / "link.csv").symlink_to(inp)

    def plan(inputs, outs):
        p = Outputs()
        for label, path in inputs.items():
            p.input(label, path)
        for label, path in outs.items():
            p.file(label, path)
        return p.check()

    with pytest.raises(InputError, match="--out: .*link.csv is the input data"):
        plan({"data": inp}, {"--out": tmp_path / "link.csv"})
    with pytest.raises(InputError, match="--b: .* is also written as --a"):
        plan({}, {"--a": tmp_path / "o.csv", "--b": tmp_path / "." / "o.csv"})
    with pytest.raises(InputError, match="o.csv is also written as .*o.csv; two outputs"):
        write_files_atomic([(tmp_path / "o.csv", "a"), (tmp_path / "." / "o.csv", "b")])
    with pytest.raises(InputError, match="directory .* does not exist"):
        write_files_atomic([(tmp_path / "nope" / "o.csv", "a")])
    assert plan({"data": inp}, {"--out": tmp_path / "new" / "o.csv"}).files == [("--out", tmp_path / "new" / "o.csv")]
    assert (tmp_path / "new").is_dir()


def test_reproduce_default_never_writes_the_shipped_report(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    code, _, err = cli(["reproduce", "--scene", "paper_fixed_link1", "--regenerate-shipped"], capsys)
    assert_one_line_error(code, err, "--regenerate-shipped")
    from userio.outputs import default_dir
    d = default_dir(None, default="reproduction", shipped_dir=REPO_ROOT / "reports")
    assert d == tmp_path / "reproduction"
    monkeypatch.chdir(REPO_ROOT)
    with pytest.raises(InputError, match="shipped reports directory"):
        default_dir(None, default="reports", shipped_dir=REPO_ROOT / "reports")


# --------------------------------------------------------------------------- numbers and files
@pytest.mark.parametrize("argv, match", [
    (["bridge", "--strain-per-Nm", "inf"], "--strain-per-Nm: expected a finite number"),
    (["bridge", "--bandwidth-Hz", "nan"], "--bandwidth-Hz: expected a finite number"),
    (["calibrate", "{d}/s.csv", "--out", "{d}/x.json", "--lever-arm-m", "inf"], "--lever-arm-m"),
    (["calibrate", "{d}/s.csv", "--out", "{d}/x.json", "--mass-std-g", "nan"], "--mass-std-g"),
    (["calibrate", "{d}/s.csv", "--out", "{d}/x.json", "--seed", "-1"], "--seed"),
    (["acquire", "--port", "loop://", "--out", "{d}/r.bin", "--guided", "0,10", "--settle-s", "nan"],
     "--settle-s"),
    (["acquire", "--port", "loop://", "--out", "{d}/r.bin", "--guided", "0,inf"], "--guided"),
    (["acquire", "--port", "loop://", "--out", "{d}/r.bin", "--guided", "0,10", "--settle-s", "1e308"],
     "--settle-s: must be ≤ 3600"),
    (["acquire", "--port", "loop://", "--out", "{d}/r.bin", "--rate-hz", "1e300"], "--rate-hz"),
    (["demo", "--seed", "-1"], "--seed"),
    (["simulate", str(SCENES / "paper_fixed_link1.toml"), "--out", "{d}/a.csv", "--seed", "-1"],
     "--seed"),
    (["simulate", str(SCENES / "paper_fixed_link1.toml"), "--out", "{d}/a.csv", "--duration", "inf"],
     "--duration"),
    (["propagate", "--seed", "-1"], "--seed"),
])
def test_non_finite_and_negative_numbers_exit_2(work, capsys, argv, match):
    before = snapshot(work)
    code, _, err = cli([a.replace("{d}", str(work)) for a in argv], capsys)
    assert_one_line_error(code, err, match)
    assert snapshot(work) == before


@pytest.mark.parametrize("readings, match", [
    ("5.0\n" * 12, "all 12 readings are 5"),
    ("8388607\n" * 12, "all 12 readings are 8.38861e+06"),
])
def test_constant_or_saturated_calibration_readings_exit_2(tmp_path, capsys, readings, match):
    rows = readings.strip().splitlines()
    text = "mass_g,reading\n" + "".join(f"{10 * (i % 4)},{r}\n" for i, r in enumerate(rows))
    (tmp_path / "c.csv").write_text(text)
    code, _, err = cli(["calibrate", tmp_path / "c.csv", "--out", tmp_path / "c.json"], capsys)
    assert_one_line_error(code, err, match)
    assert not (tmp_path / "c.json").exists()


def test_mostly_saturated_counts_exit_2(tmp_path, capsys):
    m = np.repeat([0, 100, 200, 300, 400], 3)
    r = np.where(m >= 200, 2 ** 23 - 1, 1000 * m + 5)
    (tmp_path / "c.csv").write_text("# reading_unit=counts\nmass_g,reading\n"
                                    + "".join(f"{a},{b}\n" for a, b in zip(m, r)))
    code, _, err = cli(["calibrate", tmp_path / "c.csv", "--out", tmp_path / "c.json"], capsys)
    assert_one_line_error(code, err, "ADC full scale (saturated)")


def _rehashed(work, mutate):
    doc = json.loads((work / "cal.json").read_text())
    mutate(doc)
    (work / "bad.json").write_bytes(encode(doc))       # valid hash: only the meaning is wrong
    return work / "bad.json"


@pytest.mark.parametrize("mutate, match", [
    (lambda d: d["coefficients"].__setitem__("slope", 0.0), "slope is 0"),
    (lambda d: d.__setitem__("lever_arm_m", -0.2), "lever_arm_m: must be > 0"),
    (lambda d: d.__setitem__("model", "cubic"), "model: must be 'linear', 'quadratic' or 'hysteresis', got 'cubic'"),
    (lambda d: d.pop("covariance"), "covariance: missing field"),
    (lambda d: d["covariance"].__setitem__("matrix", [[1.0, 0.0], [0.0, -1.0]]),
     "not positive semi-definite"),
    (lambda d: d["covariance"].__setitem__("matrix", [[1.0, 0.5], [0.0, 1.0]]), "not symmetric"),
    (lambda d: d["coefficients"].__setitem__("slope", None), "coefficients.slope"),
    (lambda d: d["samples"].__setitem__("values", [[1.0]]), "samples.values"),
])
def test_hash_valid_calibration_without_meaning_exit_2(work, capsys, mutate, match):
    bad = _rehashed(work, mutate)
    code, _, err = cli(["apply", bad, work / "s.csv"], capsys)
    assert_one_line_error(code, err, match)


def test_apply_flags_instead_of_extrapolating(work, capsys):
    (work / "r.csv").write_text("reading\n5.5\n1e300\n30\n-1e6\n")
    code, out, err = cli(["apply", work / "cal.json", work / "r.csv", "--json"], capsys)
    assert code == 0, err
    res = json.loads(out)
    assert res["outside_calibrated_range"] == 3 and res["out_of_range"] == 3
    tau = res["torque_Nm"]
    assert tau[0] is not None and 0 < tau[0] < 1 and tau[1:] == [None, None, None]
    # 16 mV ↔ ≈ 960 g: inside the calibrated 0–990 g, so it is kept
    (work / "r2.csv").write_text("reading\n16\n")
    code, out, _ = cli(["apply", work / "cal.json", work / "r2.csv", "--json"], capsys)
    assert json.loads(out)["torque_Nm"][0] is not None


def test_apply_flags_saturated_adc_counts(work, capsys):
    doc = json.loads((work / "cal.json").read_text())
    doc["reading_unit"] = "counts"
    doc["coefficients"] = {"slope": 1000.0, "offset": 0.0}
    doc["calibrated_range"] = {"mass_g_min": 0.0, "mass_g_max": 1e5, "reading_min": 0.0,
                               "reading_max": 1e8}
    (work / "c.json").write_bytes(encode(doc))
    (work / "r.csv").write_text("reading\n50000\n8388607\n-8388608\n")
    code, out, err = cli(["apply", work / "c.json", work / "r.csv", "--out", work / "t.csv",
                          "--json"], capsys)
    assert code == 0, err
    res = json.loads(out)
    assert res["saturated_adc"] == 2 and res["mass_g"][0] == pytest.approx(50.0)
    text = (work / "t.csv").read_text().splitlines()
    assert text[0].endswith(",flag") and text[2].endswith("saturated_adc")


# --------------------------------------------------------------------------- scene checks
@pytest.mark.parametrize("edit, match", [
    (lambda s: s.replace("rtol = 1e-6", "rtol = 1.0"), "integrator.rtol: must be ≤ 0.01, got 1.0"),
    (lambda s: s.replace("atol = 1e-8", "atol = 0.5"), "integrator.atol: must be ≤ 0.01, got 0.5"),
])
def test_scene_tolerances_outside_sensible_range_exit_2(tmp_path, capsys, edit, match):
    scene = tmp_path / "s.toml"
    scene.write_text(edit((SCENES / "paper_fixed_link1.toml").read_text()))
    code, _, err = cli(["simulate", scene, "--out", tmp_path / "a.csv"], capsys)
    assert_one_line_error(code, err, match)


def test_scene_torque_noise_ignored_by_bridge_model_exit_2(tmp_path, capsys):
    text = (SCENES / "paper_fixed_link1.toml").read_text()
    assert 'torque_model = "bridge"' in text and "torque_noise_Nm" not in text
    text = text.replace("[sensors]", "[sensors]\ntorque_noise_Nm = 0.5", 1)
    scene = tmp_path / "s.toml"
    scene.write_text(text)
    code, _, err = cli(["simulate", scene, "--out", tmp_path / "a.csv"], capsys)
    assert_one_line_error(code, err, "torque_noise_Nm: is ignored with torque_model")


@pytest.mark.parametrize("argv", [["propagate", "--grid", "100000"],
                                  ["propagate", "--draws", "100000000"]])
def test_propagate_runaway_size_refused_before_any_work(capsys, argv):
    """--grid 100000 or --draws 1e8 used to end in MemoryError; now the size is refused up front."""
    code, _, err = cli(argv, capsys)
    assert_one_line_error(code, err, "--max-localizations")
