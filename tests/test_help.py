"""The CLI explains itself: --version, usage on a bare call, every option with help (unit and
default), an example under every subcommand's --help that parses and names only files that exist
in the repository (the cheap ones are run), the same --out/--out-dir rules everywhere, and the
top-level error paths (Ctrl-C, broken pipe, undecodable input, bugs)."""

import argparse
import json
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

import torquebench
from torquebench import cli
from torquebench.cli import build_parser, main

ROOT = Path(__file__).resolve().parents[1]
SHIPPED = ("robots", "scenes", "designs", "sensors", "calibration", "flexure", "bridge", "estimator", "examples")
INPUT_SUFFIXES = (".csv", ".toml", ".json")
# examples cheap enough to run in the suite (the rest are parsed and their inputs checked)
RUN = ("bridge", "estimate", "simulate", "apply", "report --list")


def _tb(*argv, cwd=ROOT, **kw):
    return subprocess.run([sys.executable, "-m", "torquebench", *map(str, argv)], cwd=cwd,
                          capture_output=True, text=True, timeout=300, **kw)


@pytest.fixture
def tb(cli_inprocess):
    """``main`` in-process for the tests of a command's contract (exit code, one-line error,
    files kept, usage on a bare call, the help's examples); ``_tb`` stays where the process is
    what is tested: ``python -m torquebench --version`` (the entry point) and the broken pipe."""
    return cli_inprocess


def _subparsers() -> dict:
    action = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    return action.choices


def _help_examples() -> list[tuple[str, str]]:
    out = []
    for name, sub in _subparsers().items():
        for line in (sub.epilog or "").splitlines():
            if line.strip().startswith("torquebench "):
                out.append((name, line.strip()))
    return out


def test_version():
    proc = _tb("--version")
    assert proc.returncode == 0 and proc.stdout.strip() == f"torquebench {torquebench.__version__}"


def test_bare_call_shows_usage_and_every_command(tb):
    proc = tb()
    assert proc.returncode == 2 and proc.stdout == ""
    assert proc.stderr.startswith("usage: torquebench")
    for name in _subparsers():
        assert re.search(rf"^\s+{re.escape(name)}\b", proc.stderr, flags=re.M), name


def test_top_level_help_is_plain_text():
    text = build_parser().format_help()
    assert "``" not in text and "`" not in text
    assert "Start here:" in text and "examples/leg_poke/leg_poke.csv" in text


@pytest.mark.parametrize("name", sorted(_subparsers()))
def test_every_option_has_help_and_shows_its_default(name):
    sub = _subparsers()[name]
    for action in sub._actions:
        if isinstance(action, argparse._HelpAction):
            continue
        label = action.option_strings[0] if action.option_strings else action.dest
        assert action.help and action.help.strip(), f"{name} {label}: no help text"
        has_default = action.default not in (None, False) and action.nargs != 0
        if has_default and action.option_strings:
            assert "default" in action.help, f"{name} {label}: default {action.default!r} not shown"


@pytest.mark.parametrize("name", sorted(_subparsers()))
def test_every_subcommand_help_has_an_example(name):
    text = _subparsers()[name].format_help()
    assert "\nExample:\n" in text
    assert any(cmd == name for cmd, _ in _help_examples())


@pytest.mark.parametrize("name,example", _help_examples())
def test_help_example_parses_and_its_inputs_exist(name, example):
    argv = shlex.split(example)
    args = build_parser().parse_args(argv[1:])         # SystemExit on a bad option
    assert args.command == name
    for token in argv[2:]:
        if token.endswith(INPUT_SUFFIXES) and not token.startswith(("out/", "/")):
            assert (ROOT / token).is_file(), f"{example}: {token} is not in the repository"
        assert "../" not in token, example


@pytest.mark.parametrize("name,example", [e for e in _help_examples()
                                          if any(e[1].startswith(f"torquebench {r}") for r in RUN)])
def test_cheap_help_examples_run(name, example, tmp_path, tb):
    work = tmp_path / "repo"
    work.mkdir()
    for d in SHIPPED:
        (work / d).symlink_to(ROOT / d)
    argv = shlex.split(example)
    proc = tb(*argv[1:], cwd=work)          # as typed, in a checkout's layout: the relative paths resolve there
    assert proc.returncode == 0, f"{example}\n{proc.stderr[-2000:]}"
    if "--json" in argv:
        json.loads(proc.stdout)


# ---- --out / --out-dir: create what is missing, never replace what the user stored --------------

LOG = ROOT / "examples" / "sim" / "paper_fixed_link2.csv"


def test_out_creates_missing_directories_and_keeps_existing_files(tmp_path, tb):
    out = tmp_path / "a" / "b" / "est.csv"
    assert tb("estimate", LOG, "--out", out).returncode == 0 and out.is_file()
    out.write_text("mine")
    proc = tb("estimate", LOG, "--out", out)
    assert proc.returncode == 2 and "--force" in proc.stderr and len(proc.stderr.splitlines()) == 1
    assert out.read_text() == "mine"
    assert tb("estimate", LOG, "--out", out, "--force").returncode == 0
    assert out.read_text().startswith("t,contact")


def test_simulate_keeps_an_existing_truth_file(tmp_path, tb):
    (tmp_path / "log.truth.csv").write_text("mine")
    proc = tb("simulate", ROOT / "scenes" / "paper_fixed_link2.toml", "--out", tmp_path / "log.csv",
               "--duration", "0.05")
    assert proc.returncode == 2 and "exists" in proc.stderr
    assert (tmp_path / "log.truth.csv").read_text() == "mine" and not (tmp_path / "log.csv").exists()


def test_out_dir_is_created_by_report(tmp_path, tb):
    target = tmp_path / "new" / "reports"
    proc = tb("report", "--only", "bridge", "--out-dir", target)
    assert proc.returncode == 0, proc.stderr
    assert (target / "bridge.md").is_file()
    index = (target / "README.md").read_text()
    assert "[Bridge" in index and "Regenerate: `torquebench report --only bridge`" in index


def test_out_dir_that_is_a_file_is_a_user_error(tmp_path, tb):
    (tmp_path / "f").write_text("x")
    proc = tb("report", "--only", "bridge", "--out-dir", tmp_path / "f")
    assert proc.returncode == 2 and "not a directory" in proc.stderr
    assert len(proc.stderr.strip().splitlines()) == 1


# ---- top-level error paths ------------------------------------------------------------------

def _patched_run(monkeypatch, exc):
    def boom(args):
        raise exc
    monkeypatch.setattr(cli, "_commands", lambda real=cli._commands: {
        n: (type("M", (), {"HELP": m.HELP, "add_arguments": staticmethod(m.add_arguments),
                           "run": staticmethod(boom)}) if n == "bridge" else m)
        for n, m in real().items()})


def test_ctrl_c_exits_130_with_one_line(monkeypatch, capsys):
    _patched_run(monkeypatch, KeyboardInterrupt())
    assert main(["bridge"]) == 130
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "interrupted" in err


def test_unexpected_exception_is_one_line_naming_a_bug(monkeypatch, capsys):
    _patched_run(monkeypatch, ZeroDivisionError("division by zero"))
    assert main(["bridge"]) == 1
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1
    assert "bug" in err and "--debug" in err and "Traceback" not in err


def test_debug_shows_the_traceback_of_a_bug(monkeypatch):
    _patched_run(monkeypatch, ZeroDivisionError("division by zero"))
    with pytest.raises(ZeroDivisionError):
        main(["--debug", "bridge"])


def test_undecodable_input_is_a_user_error(tmp_path, tb):
    bad = tmp_path / "log.csv"
    bad.write_bytes(b"\xff\xfe\x00\x01t,q1\n\x9f\x00")
    proc = tb("estimate", bad)
    assert proc.returncode == 2 and proc.stdout == ""
    assert len(proc.stderr.strip().splitlines()) == 1 and "Traceback" not in proc.stderr


def test_unicode_error_raised_by_a_command_exits_2(monkeypatch, capsys):
    _patched_run(monkeypatch, UnicodeDecodeError("utf-8", b"\xff", 0, 1, "invalid start byte"))
    assert main(["bridge"]) == 2
    assert "not UTF-8" in capsys.readouterr().err


BIG_OUTPUT = """
import sys
from torquebench import cli
real = cli._commands
def loud(args):
    for i in range(10**6):
        print(f"line {i} " + "x" * 60)
    return 0
def patched():
    mods = real()
    m = mods["bridge"]
    mods["bridge"] = type("M", (), {"HELP": m.HELP, "add_arguments": staticmethod(m.add_arguments),
                                    "run": staticmethod(loud)})
    return mods
cli._commands = patched
sys.exit(cli.main(["bridge"]))
"""


def test_broken_pipe_is_quiet():
    """`torquebench estimate LOG | head -1`: the reader leaves early; no traceback, no error.
    The command prints 60 MB so the pipe really breaks (a short output would fit its buffer)."""
    proc = subprocess.run(f"{shlex.quote(sys.executable)} -c {shlex.quote(BIG_OUTPUT)} | head -1; "
                          "exit ${PIPESTATUS[0]}", shell=True, cwd=ROOT, capture_output=True,
                          text=True, timeout=300, executable="/bin/bash")
    assert proc.stdout == "line 0 " + "x" * 60 + "\n"
    assert proc.returncode == 0, proc.stderr
    assert proc.stderr == ""


def test_demo_says_what_each_file_is(tmp_path, tb):
    proc = tb("demo", "--out-dir", tmp_path / "d", "--json")
    assert proc.returncode == 0, proc.stderr
    files = json.loads(proc.stdout)["files"]
    assert sorted(Path(p).name for p in files) == ["estimate_dynamic.csv", "estimate_paper.csv",
                                                  "log.csv", "log.truth.csv"]
    for path, what in files.items():
        assert Path(path).is_file() and len(what) > 20, path
