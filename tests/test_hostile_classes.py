"""Hostile input, round two (issue 25): one test per rule that closes a class, each on inputs other
than the issue's examples where that is cheap (other factors, other channels, other logs). The
CLI runs in-process; every refusal is exit 2 and ONE line; nothing that existed is changed."""

import json
import os
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from torquebench.cli import main
from torquebench.io import REPO_ROOT

SIM = REPO_ROOT / "examples" / "sim"
SCENES = REPO_ROOT / "scenes"
DATA = REPO_ROOT / "calibration" / "data"


def cli(argv, capsys):
    try:
        code = main([str(a) for a in argv])
    except SystemExit as exc:
        code = exc.code
    out, err = capsys.readouterr()
    return code, out, err


def one_line(code, err, *needles):
    assert code == 2, err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in err, err
    for n in needles:
        assert n in lines[0], lines[0]
    return lines[0]


def snapshot(d: Path) -> dict:
    return {str(p.relative_to(d)): (os.readlink(p) if p.is_symlink() else p.read_bytes())
            for p in sorted(d.rglob("*")) if p.is_file() or p.is_symlink()}


@pytest.fixture()
def logs(tmp_path):
    for stem, new in (("paper_fixed_link2", "fixed"), ("paper_floating_link1", "float")):
        for suf in (".csv", ".timing.toml", ".noise.toml"):
            shutil.copy(SIM / f"{stem}{suf}", tmp_path / f"{new}{suf}")
    shutil.copy(REPO_ROOT / "robots" / "paper_leg.toml", tmp_path / "robot.toml")
    return tmp_path


# ============================================================================ data loss
@pytest.mark.parametrize("target, alias", [("fixed.timing.toml", "{d}/sub/../fixed.timing.toml"),
                                           ("fixed.noise.toml", "{d}/fixed.noise.toml"),
                                           ("robot.toml", "{d}/link.toml"),
                                           ("fixed.csv", "{d}/hard.csv")])
def test_estimate_never_writes_its_log_side_files_or_robot(logs, capsys, target, alias):
    (logs / "sub").mkdir()
    os.symlink("robot.toml", logs / "link.toml")
    os.link(logs / "fixed.csv", logs / "hard.csv")
    before = snapshot(logs)
    code, _, err = cli(["estimate", logs / "fixed.csv", "--robot", logs / "robot.toml", "--out",
                        alias.format(d=logs), "--force"], capsys)
    one_line(code, err, "refusing to overwrite an input")
    assert snapshot(logs) == before


def test_estimate_out_on_an_absent_side_file_name_is_refused(logs, capsys):
    """LOG.timing.toml that does not exist yet: writing it would change what the log means."""
    (logs / "fixed.timing.toml").unlink()
    code, _, err = cli(["estimate", logs / "fixed.csv", "--out", logs / "fixed.timing.toml"], capsys)
    one_line(code, err, "side file")
    assert not (logs / "fixed.timing.toml").exists()


@pytest.mark.parametrize("suffix", [".truth.csv", ".timing.toml", ".noise.toml"])
def test_simulate_never_writes_the_robot_its_scene_reads(tmp_path, capsys, suffix):
    robot = tmp_path / f"sim{suffix}"
    shutil.copy(REPO_ROOT / "robots" / "paper_leg.toml", robot)
    scene = (SCENES / "paper_fixed_link1.toml").read_text().replace(
        'robot = "paper_leg.toml"', f'robot = "{robot.name}"')
    (tmp_path / "s.toml").write_text(scene)
    before = snapshot(tmp_path)
    code, _, err = cli(["simulate", tmp_path / "s.toml", "--out", tmp_path / "sim.csv", "--force"], capsys)
    one_line(code, err, "is the input robot")
    assert snapshot(tmp_path) == before


def test_compare_png_is_never_the_scene_nor_an_existing_file(tmp_path, capsys):
    scene = tmp_path / "e.png"                     # a scene named like the picture
    scene.write_text((SCENES / "paper_floating_link2.toml").read_text())
    (tmp_path / "mine.png").write_bytes(b"user picture")
    before = snapshot(tmp_path)
    code, _, err = cli(["compare", scene, "--vary", "sensors.seed=1", "--png", scene], capsys)
    one_line(code, err, "is the input scene")
    code, _, err = cli(["compare", scene, "--vary", "sensors.seed=1", "--png", tmp_path / "mine.png"], capsys)
    one_line(code, err, "mine.png exists; add --force")
    assert snapshot(tmp_path) == before


def test_scene_names_stay_in_the_report_directory(tmp_path, monkeypatch):
    from torquebench.outputs import run_plan
    from torquebench.pipeline import report_dir, summary_name
    from torquebench.scenes import load_scene

    monkeypatch.chdir(tmp_path)
    text = (SCENES / "paper_floating_link2.toml").read_text()
    for name in ("../../escaped", "/abs/path", "..", "a/b/c"):
        (tmp_path / "s.toml").write_text(text.replace('name = "paper_floating_link2"', f'name = "{name}"')
                                         + '\n[outputs]\nwant = ["report"]\nreports = ["bridge"]\n')
        scene = load_scene(tmp_path / "s.toml")
        d = report_dir(scene)
        assert d.parent == Path("out") and ".." not in d.parts and "/" not in summary_name(scene)
        plan = run_plan(scene)
        assert all(tmp_path / "out" in (tmp_path / p).resolve().parents for _, p in plan.files)


def test_a_scene_named_like_a_user_file_does_not_replace_it(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "notes.md").write_text("my notes")
    text = (SCENES / "paper_floating_link2.toml").read_text().replace(
        'name = "paper_floating_link2"', 'name = "notes"')
    (tmp_path / "s.toml").write_text(text + '\n[outputs]\nwant = ["report"]\nreports = ["bridge"]\n'
                                     'dir = "."\n')
    code, _, err = cli(["run", tmp_path / "s.toml"], capsys)
    one_line(code, err, "notes.md exists; add --overwrite")
    assert (tmp_path / "notes.md").read_text() == "my notes"


def test_cache_clear_deletes_only_its_own_entries(tmp_path, capsys):
    from torquebench.cache import Cache

    d = tmp_path / "c"
    d.mkdir()
    (d / "model.pkl").write_bytes(b"mine")
    (d / ("b" * 64 + ".pkl")).write_bytes(b"mine too, named like an entry")
    c = Cache(d)
    c.put("a" * 32, {"x": 1})
    assert c.get("a" * 32) == {"x": 1} and c.get("b" * 64) is None   # not the cache's: never read
    code, out, err = cli(["cache", "clear", "--cache-dir", d, "--json"], capsys)
    assert code == 0 and json.loads(out)["removed"] == 1, err
    assert sorted(p.name for p in d.iterdir()) == sorted(["model.pkl", "b" * 64 + ".pkl"])


def test_cache_dir_that_is_a_file_is_one_line(tmp_path, capsys):
    f = tmp_path / "f"
    f.write_text("x")
    code, _, err = cli(["run", SCENES / "paper_fixed_link1.toml", "--cache-dir", f], capsys)
    one_line(code, err, "is not a directory")
    assert f.read_text() == "x"


def test_acquire_appends_to_a_kept_capture_and_refuses_a_symlinked_one(tmp_path, capsys):
    notes = tmp_path / "notes.md"
    notes.write_text("mine")
    os.symlink("notes.md", tmp_path / "cap.bin.part")
    code, _, err = cli(["acquire", "--port", "loop://", "--out", tmp_path / "cap.bin",
                        "--duration-s", "0.1", "--force"], capsys)
    one_line(code, err, "is a symlink")
    assert notes.read_text() == "mine"
    (tmp_path / "cap.bin.part").unlink()
    (tmp_path / "cap.bin.part").write_bytes(b"\xa5\x5a kept bytes")
    code, _, err = cli(["acquire", "--port", "loop://", "--out", tmp_path / "cap.bin",
                        "--duration-s", "0.1"], capsys)
    assert code == 0, err
    assert (tmp_path / "cap.bin").read_bytes().startswith(b"\xa5\x5a kept bytes")


@pytest.mark.parametrize("argv, name", [
    (["demo", "--out-dir", "{d}"], "estimate_paper.csv"),
    (["report", "--only", "bridge", "--out-dir", "{d}"], "bridge.md"),
    (["reproduce", "--scene", "paper_fixed_link1", "--no-stiffness", "--out-dir", "{d}"],
     "paper_reproduction.md"),
])
def test_out_dir_commands_keep_the_users_files(tmp_path, capsys, argv, name):
    """README: --out-dir never replaces a file you stored without --force (refused before work)."""
    d = tmp_path / "od"
    d.mkdir()
    (d / name).write_text("mine")
    code, _, err = cli([a.replace("{d}", str(d)) for a in argv], capsys)
    one_line(code, err, "--force")
    assert (d / name).read_text() == "mine" and sorted(p.name for p in d.iterdir()) == [name]


def test_demo_replaces_its_own_files_but_not_an_edited_one(tmp_path, capsys):
    d = tmp_path / "d"
    for _ in range(2):
        code, _, err = cli(["demo", "--out-dir", d, "--json"], capsys)
        assert code == 0, err
    (d / "log.csv").write_text("edited")
    code, _, err = cli(["demo", "--out-dir", d, "--json"], capsys)
    one_line(code, err, "log.csv exists")
    assert (d / "log.csv").read_text() == "edited"


# ============================================================================ OS errors
def test_a_full_disk_at_the_final_write_is_one_line_and_leaves_nothing(logs, capsys, monkeypatch):
    import errno

    import userio.outputs as O

    def full(tmp, path, mode):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(path))

    monkeypatch.setattr(O, "place", full)
    monkeypatch.setattr("userio.files.place", full, raising=False)
    before = snapshot(logs)
    code, _, err = cli(["estimate", logs / "fixed.csv", "--out", logs / "e.csv"], capsys)
    one_line(code, err, "e.csv", "full")
    assert snapshot(logs) == before


@pytest.mark.parametrize("kind", ["dir", "fifo"])
@pytest.mark.parametrize("argv", [["estimate", "{x}"], ["simulate", "{x}", "--out", "o.csv"],
                                  ["calibrate", "{x}", "--out", "c.json"], ["bridge", "{x}"],
                                  ["apply", "{cal}", "{x}"], ["flexure", "{x}"], ["run", "{x}"]])
def test_inputs_that_are_directories_or_devices_say_so(tmp_path, capsys, monkeypatch, argv, kind):
    monkeypatch.chdir(tmp_path)
    x = tmp_path / "thing"
    x.mkdir() if kind == "dir" else os.mkfifo(x)
    argv = [a.format(x=x, cal=DATA / "paper_link1_cal.json") for a in argv]
    code, _, err = cli(argv, capsys)
    line = one_line(code, err, "thing")
    assert ("directory" if kind == "dir" else "FIFO") in line and "not found" not in line


def test_dask_host_that_does_not_resolve_is_one_line(capsys):
    code, _, err = cli(["sweep", SCENES / "paper_floating_link2.toml", "--vary", "sensors.seed=1,2",
                        "--executor", "dask://no-such-host.invalid:8786"], capsys)
    one_line(code, err, "--executor")


# ============================================================================ Ctrl-C
def test_ctrl_c_anywhere_is_130_and_one_line(monkeypatch, capsys, tmp_path):
    import torquebench.commands.bridge as B

    def boom(args):
        raise KeyboardInterrupt

    monkeypatch.setattr(B, "run", boom)
    code, _, err = cli(["bridge"], capsys)
    assert code == 130 and len(err.strip().splitlines()) == 1 and "interrupted" in err


def test_ctrl_c_inside_a_c_callback_becomes_a_keyboard_interrupt():
    from userio.errors import CallbackInterrupt

    guard = CallbackInterrupt()

    def size(*a):
        raise KeyboardInterrupt

    cb = guard.wrap(size, 0.0)
    assert cb(1, 2) == 0.0 and cb(1, 2) == 0.0           # C code sees "stop", no traceback printed
    with pytest.raises(KeyboardInterrupt):
        guard.check()
    guard.check()                                        # raised once


# ============================================================================ nonsense → refused or warned
def _edit(src: Path, dst: Path, fn):
    d = pd.read_csv(src)
    fn(d)
    d.to_csv(dst, index=False, float_format="%.10g")


@pytest.mark.parametrize("log, fn, needle", [
    ("fixed", lambda d: d.__setitem__(["tau1", "tau2"], d[["tau1", "tau2"]] * 1000.0), "N·mm"),
    ("float", lambda d: d.__setitem__(["tau1", "tau2"], d[["tau1", "tau2"]] * 1000.0), "N·mm"),
    ("float", lambda d: d.__setitem__(["Fx", "Fz"], d[["Fx", "Fz"]] / 1000.0), "kN"),
    ("fixed", lambda d: d.__setitem__(["Fx", "Fz"], d[["Fz", "Fx"]].to_numpy()), "swapped"),
    ("float", lambda d: d.__setitem__(["Fx", "Fz"], d[["Fz", "Fx"]].to_numpy()), "swapped"),
    ("fixed", lambda d: d.__setitem__("Fz", -d["Fz"]), "sign"),
    ("float", lambda d: d.__setitem__(["Fx", "Fz", "My", "tau1", "tau2"], 0.0), "exactly 0"),
])
def test_logs_in_wrong_units_or_channels_are_refused_naming_the_cause(logs, capsys, log, fn, needle):
    _edit(logs / f"{log}.csv", logs / "bad.csv", fn)
    code, _, err = cli(["estimate", logs / "bad.csv"], capsys)
    one_line(code, err, needle)


@pytest.mark.parametrize("log, col", [("fixed", "tau2"), ("float", "My"), ("float", "tau1")])
def test_a_dead_channel_is_warned_not_answered_silently(logs, capsys, log, col):
    _edit(logs / f"{log}.csv", logs / "dead.csv", lambda d: d.__setitem__(col, 0.0))
    code, out, err = cli(["estimate", logs / "dead.csv", "--json"], capsys)
    assert code == 0, err
    warnings = json.loads(out).get("warnings", [])
    assert any(f"'{col}'" in w or f" {col} " in w for w in warnings), warnings
    assert f"warning: " in err


@pytest.mark.parametrize("log", ["fixed", "float"])
def test_clean_logs_carry_no_plausibility_warning(logs, capsys, log):
    code, out, err = cli(["estimate", logs / f"{log}.csv", "--json"], capsys)
    assert code == 0 and "warnings" not in json.loads(out) and "warning" not in err, err


def test_the_wrong_robot_file_is_warned(logs, capsys):
    text = (logs / "robot.toml").read_text().replace("mass_kg = 0.351", "mass_kg = 0.9")
    (logs / "heavy.toml").write_text(text)
    code, out, err = cli(["estimate", logs / "float.csv", "--robot", logs / "heavy.toml", "--json"], capsys)
    assert code != 0 or json.loads(out).get("warnings"), err


@pytest.mark.parametrize("argv, needles", [
    (["estimate", "{d}/fixed.csv", "--gain", "1e-300"], ("--gain", "1/s")),
    (["estimate", "{d}/fixed.csv", "--gain", "3e9"], ("--gain", "1/s")),
    (["estimate", "{d}/fixed.csv", "--torque-sigma", "1e300"], ("torque sigma", "N·m")),
    (["estimate", "{d}/fixed.csv", "--torque-sigma", "1e-300"], ("torque sigma", "N·m")),
    (["estimate", "{d}/fixed.csv", "--ft-sigma", "0.1,2e-200,0.01"], ("FT sigma",)),
    (["estimate", "{d}/fixed.csv", "--velocity-sigma", "5e4"], ("velocity sigma", "rad/s")),
    (["estimate", "{d}/fixed.csv", "--encoder-counts", "2"], ("encoder counts",)),
    (["estimate", "{d}/fixed.csv", "--timing", "delay:100"], ("--timing", " s ")),
    (["estimate", "{d}/fixed.csv", "--timing", "delay:1e300"], ("--timing",)),
    (["estimate", "{d}/fixed.csv", "--false-alarm-rate", "1e-30/sample"], ("--false-alarm-rate",)),
    (["estimate", "{d}/fixed.csv", "--quiet-window", "0.54:0.99"], ("--quiet-window", "contact")),
    (["estimate", "{d}/fixed.csv", "--quiet-window", "0.2:1.3"], ("--quiet-window", "contact")),
    (["propagate", "--contact", "2,0.8,1"], ("--contact", "two values")),
    (["propagate", "--gain", "1e-300"], ("--gain", "1/s")),
    (["propagate", "--rate", "1e-9"], ("--rate", "Hz")),
    (["propagate", "--ft-noise", "1e-300,1e-300,1e-300"], ("--ft-noise",)),
    (["calibrate", "{s}", "--out", "{d}/c.json", "--lever-arm-m", "205"], ("--lever-arm-m", "mm typed as m")),
    (["calibrate", "{s}", "--out", "{d}/c.json", "--walkers", "10000000"], ("--walkers",)),
    (["bridge", "--averaging", "1000000000000"], ("--averaging",)),
    (["bridge", "--strain-per-Nm", "1e-300"], ("--strain-per-Nm",)),
    (["run", SCENES / "paper_fixed_link1.toml", "--seed", "-1"], ("--seed",)),
])
def test_absurd_options_are_refused_with_their_unit(logs, capsys, argv, needles):
    before = snapshot(logs)
    argv = [str(a).replace("{d}", str(logs)).replace("{s}", str(DATA / "paper_link1_session.csv"))
            for a in argv]
    code, _, err = cli(argv, capsys)
    one_line(code, err, *needles)
    assert snapshot(logs) == before


@pytest.mark.parametrize("edit, needles", [
    (("length_m = 0.215", "length_m = 215.0"), ("link[2].length_m", "mm typed as m")),
    (("mass_kg = 0.080", "mass_kg = 80000.0"), ("link[2].mass_kg", "kg")),
    (("gravity_m_per_s2 = 9.81", "gravity_m_per_s2 = 0.0"), ("gravity_m_per_s2", "m/s²")),
    (("inertia_kgm2 = 0.00030", "inertia_kgm2 = 3e5"), ("inertia_kgm2", "kg·m²")),
])
def test_robot_fields_outside_physics_are_refused(logs, capsys, edit, needles):
    (logs / "r.toml").write_text((logs / "robot.toml").read_text().replace(*edit))
    code, _, err = cli(["estimate", logs / "fixed.csv", "--robot", logs / "r.toml"], capsys)
    one_line(code, err, *needles)


@pytest.mark.parametrize("edit, needles", [
    (("kp = 500.0", "kp = 3e13"), ("controller.kp", "N·m/rad")),
    (("q0_rad = [-0.4, -0.8]", "q0_rad = [-30.0, -50.0]"), ("controller.q0_rad", "degrees")),
    (("q0_rad = [-0.4, -0.8]", "q0_rad = [-0.4, -0.8]\namplitude_rad = [0.1, 0.1]\nfrequency_Hz = [3e5, 1.0]"),
     ("controller.frequency_Hz",)),
    (("t_on_s = 0.5\nt_off_s = 1.0", "t_on_s = 2.5\nt_off_s = 3.0"), ("t_on_s", "after the end")),
    (("ft_noise = [0.1, 0.1, 0.01]", "ft_noise = [0.1, 3e9, 0.01]"), ("sensors.ft_noise",)),
    (("magnitude_N = 5.0", "magnitude_N = 2e8"), ("magnitude_N", "N")),
])
def test_scene_fields_outside_physics_are_refused_naming_the_field(tmp_path, capsys, edit, needles):
    text = (SCENES / "paper_fixed_link1.toml").read_text()
    assert edit[0] in text
    (tmp_path / "s.toml").write_text(text.replace(*edit))
    code, _, err = cli(["simulate", tmp_path / "s.toml", "--out", tmp_path / "o.csv"], capsys)
    one_line(code, err, *needles)
    assert not (tmp_path / "o.csv").exists()


def test_frequency_within_range_but_above_nyquist_names_the_cause(tmp_path, capsys):
    text = (SCENES / "paper_fixed_link1.toml").read_text().replace(
        "q0_rad = [-0.4, -0.8]", "q0_rad = [-0.4, -0.8]\namplitude_rad = [0.1, 0.1]\nfrequency_Hz = [1.0, 80.0]")
    text = text.replace("sample_rate_Hz = 1000.0", "sample_rate_Hz = 100.0")
    (tmp_path / "s.toml").write_text(text)
    code, _, err = cli(["simulate", tmp_path / "s.toml", "--out", tmp_path / "o.csv"], capsys)
    one_line(code, err, "controller.frequency_Hz", "Nyquist")


def test_calibration_session_lever_arm_in_mm_is_refused(tmp_path, capsys):
    text = (DATA / "paper_link1_session.csv").read_text().replace(",0.205,", ",205,")
    (tmp_path / "s.csv").write_text(text)
    code, _, err = cli(["calibrate", tmp_path / "s.csv", "--out", tmp_path / "c.json"], capsys)
    one_line(code, err, "lever_arm_m", "mm typed as m")


@pytest.mark.parametrize("scale", [1e-300, 0.0])
def test_noise_free_or_mis_scaled_readings_are_refused_before_emcee(tmp_path, capsys, scale):
    d = pd.read_csv(DATA / "paper_link1_session.csv", comment="#")
    d["reading"] = 5.0 + 0.0115 * d["mass_g"] if scale == 0.0 else d["reading"] * scale
    (tmp_path / "s.csv").write_text("# reading_unit=mV\n" + d.to_csv(index=False))
    code, _, err = cli(["calibrate", tmp_path / "s.csv", "--out", tmp_path / "c.json"], capsys)
    one_line(code, err, "reading")


def test_apply_names_a_unit_mismatch(tmp_path, capsys):
    text = (DATA / "paper_link1_readings.csv").read_text()
    (tmp_path / "r.csv").write_text(text.replace("reading_unit=mV", "reading_unit=counts"))
    code, _, err = cli(["apply", DATA / "paper_link1_cal.json", tmp_path / "r.csv"], capsys)
    one_line(code, err, "unit mismatch", "counts", "mV")
    head, body = text.split("\n", 1)
    d = pd.read_csv(pd.io.common.StringIO(body))
    d["reading"] *= 2.0e5                                    # counts-sized, no unit declared
    (tmp_path / "r2.csv").write_text(d.to_csv(index=False))
    code, _, err = cli(["apply", DATA / "paper_link1_cal.json", tmp_path / "r2.csv"], capsys)
    one_line(code, err, "unit mismatch")


def test_flexure_material_in_pa_and_absurd_geometry_are_refused(tmp_path, capsys):
    base = (SCENES.parent / "designs" / "paper_disc.toml").read_text().replace(
        'sensor = "../sensors/paper_sensor.toml"', f'sensor = "{SCENES.parent / "sensors" / "paper_sensor.toml"}"')
    for edit, needles in ((('preset = "6061-T6"', 'preset = "6061-T6"\nE_GPa = 7.1e10'), ("E_GPa", "GPa")),
                          (("thickness_mm = 2.2", "thickness_mm = 4e200"), ("thickness_mm", "mm")),
                          (('preset = "6061-T6"', 'preset = "6061-T6"\nnu = 0.49999'), ("material.nu",))):
        (tmp_path / "d.toml").write_text(base.replace(*edit))
        code, _, err = cli(["flexure", tmp_path / "d.toml"], capsys)
        one_line(code, err, *needles)


# ============================================================================ cost before work
def test_a_wide_header_a_device_and_a_huge_file_are_refused_before_reading(tmp_path, capsys):
    (tmp_path / "wide.csv").write_text(",".join(f"c{i}" for i in range(5000)) + "\n0\n")
    code, _, err = cli(["estimate", tmp_path / "wide.csv"], capsys)
    one_line(code, err, "5000 columns")
    with open(tmp_path / "sparse.csv", "wb") as f:
        f.truncate(2 << 30)                                    # 2 GiB of zero bytes, no line end
    code, _, err = cli(["estimate", tmp_path / "sparse.csv"], capsys)
    one_line(code, err, "line 1")
    code, _, err = cli(["calibrate", tmp_path / "sparse.csv", "--out", tmp_path / "c.json"], capsys)
    one_line(code, err, "MiB")
    if Path("/dev/zero").exists():
        for argv in (["estimate", "/dev/zero"], ["bridge", "/dev/zero"], ["apply", DATA / "paper_link1_cal.json", "/dev/zero"]):
            code, _, err = cli(argv, capsys)
            one_line(code, err, "device")


def test_a_thin_disc_is_refused_before_meshing_naming_the_wall(tmp_path):
    from flexure.design import load_design, preflight
    from userio.errors import InputError

    text = (SCENES.parent / "designs" / "paper_disc.toml").read_text().replace("thickness_mm = 2.2", "thickness_mm = 0.15")
    text = text.replace('sensor = "../sensors/paper_sensor.toml"', f'sensor = "{SCENES.parent / "sensors" / "paper_sensor.toml"}"')
    (tmp_path / "thin.toml").write_text(text)
    d = load_design(tmp_path / "thin.toml")
    with pytest.raises(InputError, match="thickness_mm = 0.15 mm.*--max-elements"):
        preflight(d, levels=3)
    assert preflight(load_design(SCENES.parent / "designs" / "paper_disc.toml"), levels=3)["elements_estimate"] < 1e5


def test_calibrate_sizes_rows_and_walkers_before_allocating(tmp_path, capsys):
    rng = np.random.default_rng(3)
    m = np.tile([0, 50, 100, 200, 500, 1000], 40_000)
    r = 5 + 0.0115 * m + rng.normal(0, 0.01, m.size)
    (tmp_path / "big.csv").write_text("mass_g,reading\n" + "\n".join(f"{a},{b:.5f}" for a, b in zip(m, r)))
    code, _, err = cli(["calibrate", tmp_path / "big.csv", "--out", tmp_path / "c.json"], capsys)
    one_line(code, err, "--walkers ≤")


@pytest.mark.parametrize("cmd", ["sweep", "compare"])
def test_compare_and_sweep_exit_2_when_every_point_failed(tmp_path, capsys, cmd):
    code, out, err = cli([cmd, SCENES / "paper_floating_link2.toml", "--vary", "controller.kp=-3,-4",
                          "--executor", "local"], capsys)
    one_line(code, err, "every point failed")
    assert "FAILED" in out                                    # the table is still printed


def test_run_n_avg_sized_before_allocating(tmp_path, capsys):
    text = (SCENES / "paper_floating_link2.toml").read_text() + "\n[calibration]\nn_avg = 5000000\n"
    (tmp_path / "s.toml").write_text(text)
    code, _, err = cli(["run", tmp_path / "s.toml", "--only", "calibration"], capsys)
    one_line(code, err, "n_avg", "GiB")
