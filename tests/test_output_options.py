"""Every command's output options obey the one output policy (userio.outputs): the options are
discovered from the CLI's parsers (a new command or option fails here until it has a case), and
each is run three ways through ``torquebench.cli.main``, stopped before any work once its plan is
checked:

- its missing directory is created and the path is declared on the plan (files or directory);
- a user's file at the output (or, for a directory, a file of a name it writes) is refused
  (exit 2, one line naming the option), unchanged;
- an input given as the output is refused (exit 2), unchanged.

Inside a command, a write outside an active plan is a bug (``userio.outputs.required``).
"""

import shutil
from pathlib import Path

import pytest

from torquebench.cli import build_parser, main
from userio import outputs
from userio.errors import InputError

ROOT = Path(__file__).resolve().parents[1]
OUTPUT_DESTS = {"out", "out_dir", "png", "vtu", "csv", "session"}

# (command, option) → (argv with {OUT}, output kind "file"/"dir", a name the run writes in a
# directory output, an input file of the argv to give as the output or None)
CASES = {
    ("acquire", "--out"): (["--port", "loop://", "--out", "{OUT}", "--duration-s", "0.2"], "bin", None),
    ("acquire", "--csv"): (["--port", "loop://", "--out", "cap.bin", "--csv", "{OUT}", "--duration-s", "0.2"],
                           "csv", None),
    ("acquire", "--session"): (["--port", "loop://", "--out", "cap.bin", "--guided", "0,10", "--session", "{OUT}",
                                "--duration-s", "0.2"], "csv", None),
    ("apply", "--out"): (["cal.json", "readings.csv", "--out", "{OUT}"], "csv", "readings.csv"),
    ("calibrate", "--out"): (["session.csv", "--out", "{OUT}", "--walkers", "8", "--max-steps", "10"], "json",
                             "session.csv"),
    ("compare", "--png"): (["scene.toml", "--vary", "sensors.seed=1,2", "--png", "{OUT}"], "png", "scene.toml"),
    ("demo", "--out-dir"): (["--out-dir", "{OUT}"], "dir:log.csv", None),
    ("estimate", "--out"): (["fixed.csv", "--out", "{OUT}"], "csv", "fixed.timing.toml"),
    ("estimate", "--png"): (["fixed.csv", "--png", "{OUT}"], "png", "fixed.csv"),
    ("flexure", "--png"): (["design.toml", "--single-level", "--png", "{OUT}"], "png", None),
    ("flexure", "--vtu"): (["design.toml", "--single-level", "--vtu", "{OUT}"], "vtu", None),
    ("identify", "--out"): (["fixed.csv", "--robot", "robot.toml", "--out", "{OUT}"], "toml", "robot.toml"),
    ("propagate", "--png"): (["--grid", "2", "--draws", "10", "--png", "{OUT}"], "png", None),
    ("report", "--out-dir"): (["--only", "bridge", "--out-dir", "{OUT}"], "dir:bridge.md", None),
    ("reproduce", "--out-dir"): (["--scene", "paper_fixed_link1", "--no-stiffness", "--out-dir", "{OUT}"],
                                 "dir:reproduction.md", None),
    ("simulate", "--out"): (["scene.toml", "--out", "{OUT}"], "csv", "robot.toml"),
}


def _discovered() -> set:
    parser = build_parser()
    sub = next(a for a in parser._actions if a.__class__.__name__ == "_SubParsersAction")
    found = set()
    for name, p in sub.choices.items():
        for a in p._actions:
            if a.dest in OUTPUT_DESTS and a.option_strings and a.type is Path:
                found.add((name, a.option_strings[0]))
    return found


def test_every_output_option_has_a_case():
    assert _discovered() == set(CASES)


@pytest.fixture()
def work(tmp_path, monkeypatch):
    for stem, new in (("paper_fixed_link2", "fixed"),):
        for suf in (".csv", ".timing.toml", ".noise.toml"):
            shutil.copy(ROOT / "examples" / "sim" / f"{stem}{suf}", tmp_path / f"{new}{suf}")
    shutil.copy(ROOT / "robots" / "paper_leg.toml", tmp_path / "robot.toml")
    scene = (ROOT / "scenes" / "paper_floating_link2.toml").read_text()
    (tmp_path / "scene.toml").write_text(scene.replace('robot = "paper_leg.toml"', 'robot = "robot.toml"'))
    shutil.copy(ROOT / "sensors" / "paper_sensor.toml", tmp_path / "sensor.toml")
    design = (ROOT / "designs" / "paper_disc.toml").read_text().replace(
        'sensor = "../sensors/paper_sensor.toml"', 'sensor = "sensor.toml"')
    (tmp_path / "design.toml").write_text(design)
    data = ROOT / "calibration" / "data"
    shutil.copy(data / "paper_link1_session.csv", tmp_path / "session.csv")
    shutil.copy(data / "paper_link1_cal.json", tmp_path / "cal.json")
    shutil.copy(data / "paper_link1_readings.csv", tmp_path / "readings.csv")
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("TORQUEBENCH_CACHE", str(tmp_path / "cache"))
    return tmp_path


class _Stop(BaseException):
    """Raised once a plan is checked: the work itself is not what these tests are about."""


@pytest.fixture()
def checked_plans(monkeypatch):
    plans = []

    def stop_when_active(self):
        if not self.checked:
            self.check()
        plans.append(self)
        raise _Stop

    monkeypatch.setattr(outputs.Outputs, "active", stop_when_active)
    return plans


def _argv(cmd, opt, out):
    template = CASES[(cmd, opt)][0]
    return [cmd, *[str(out) if a == "{OUT}" else a for a in template]]


IDS = [f"{c} {o}" for c, o in CASES]
VERSIONED = {"calibrate"}              # --out: an existing file is kept, NAME.vK.json written


@pytest.mark.parametrize("cmd,opt", list(CASES), ids=IDS)
def test_a_missing_directory_is_created_and_the_output_declared(work, checked_plans, cmd, opt):
    kind = CASES[(cmd, opt)][1]
    out = work / "new" / "deeper" / ("od" if kind.startswith("dir") else f"o.{kind}")
    with pytest.raises(_Stop):
        main(_argv(cmd, opt, out))
    plan = checked_plans[-1]
    if kind.startswith("dir"):
        assert any(outputs.same_file(d, out) for _, d, _ in plan.dirs) and out.is_dir()
    else:
        assert any(outputs.same_file(p, out) for _, p in plan.files) and out.parent.is_dir()
        assert not out.exists()


@pytest.mark.parametrize("cmd,opt", list(CASES), ids=IDS)
def test_a_users_file_is_never_replaced_without_force(work, checked_plans, capsys, cmd, opt):
    kind = CASES[(cmd, opt)][1]
    if kind.startswith("dir"):
        out = work / "od"
        out.mkdir()
        mine = out / kind.split(":", 1)[1]
    else:
        out = mine = work / f"mine.{kind}"
    mine.write_text("the user's file\n")
    if cmd in VERSIONED:               # documented: the file is kept and NAME.vK written instead
        with pytest.raises(_Stop):
            main(_argv(cmd, opt, out))
        assert not any(outputs.same_file(p, mine) for _, p in checked_plans[-1].files)
    else:
        code = main(_argv(cmd, opt, out))
        err = capsys.readouterr().err.strip().splitlines()
        assert code == 2 and len(err) == 1 and str(mine.name) in err[0], err
    assert mine.read_text() == "the user's file\n"


@pytest.mark.parametrize("cmd,opt", [k for k, v in CASES.items() if v[2]], ids=[i for i, v in zip(IDS, CASES.values()) if v[2]])
def test_an_input_is_never_an_output(work, checked_plans, capsys, cmd, opt):
    target = work / CASES[(cmd, opt)][2]
    before = target.read_bytes()
    argv = _argv(cmd, opt, target) + ["--force"] * (cmd not in ("propagate",))
    code = main(argv)
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "input" in err[0], err
    assert target.read_bytes() == before


def test_a_write_outside_the_plan_is_a_bug_inside_a_command(tmp_path):
    from userio.files import write_text_atomic

    with outputs.required():
        with pytest.raises(RuntimeError, match="outside the command's output plan"):
            write_text_atomic(tmp_path / "x.txt", "x")
        plan = outputs.Outputs()
        plan.file("--out", tmp_path / "x.txt")
        with plan.active():
            write_text_atomic(tmp_path / "x.txt", "x")
    assert (tmp_path / "x.txt").read_text() == "x"
    write_text_atomic(tmp_path / "y.txt", "y")            # library use: the writer's own flag
    with pytest.raises(InputError):
        write_text_atomic(tmp_path / "y.txt", "z", overwrite=False)
