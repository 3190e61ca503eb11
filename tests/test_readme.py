"""The README's examples run as written: every `$ torquebench ...` line in a ```console block of the
README and of the documentation pages beside it (docs/*.md; the tutorials have their own test).

Commands run in a scratch directory that links the shipped inputs (robots/, scenes/, examples/, ...)
and nothing outside the repository, with a fresh `out/` for what they write; they exit 0,
and with `--json` print exactly one JSON object on stdout.
"""

import json
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SHIPPED = ("robots", "scenes", "designs", "sensors", "calibration", "flexure", "bridge", "estimator", "examples")


def readme_commands() -> list[str]:
    commands = []
    for page in [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]:
        text = page.read_text(encoding="utf-8")
        for block in re.findall(r"```console\n(.*?)```", text, flags=re.S):
            commands += [line[2:].strip() for line in block.splitlines()
                         if line.startswith("$ torquebench") and line[2:].strip() not in commands]
    return commands


def test_readme_has_examples():
    assert len(readme_commands()) >= 5


#: examples that solve a flexure's FEM (three mesh levels) or a whole sweep: a minute of CPU each;
#: and the 3-D propagate map (8 s of CPU at the README's grid), whose command line runs in the
#: default suite at a small grid (test_spatial_predict.test_propagate_3d_map_and_picture)
HEAVY = ("flexure", "compare ", "end_to_end", "reproduce", "report --only", "propagate --robot")


def _params():
    return [pytest.param(c, marks=pytest.mark.slow) if any(h in c for h in HEAVY) else c
            for c in readme_commands()]


def _scratch(tmp_path):
    work = tmp_path / "repo"
    work.mkdir()
    for name in SHIPPED:
        (work / name).symlink_to(ROOT / name)          # shipped inputs, read-only by contract
    (work / "out").mkdir()                             # everything an example writes goes here
    return work


@pytest.mark.parametrize("command", _params())
def test_readme_example_runs(command, tmp_path, cli_inprocess):
    """Each example through the CLI's ``main`` in this process (what it answers: exit code, JSON);
    the interpreter start-up and imports per example are what test_readme_example_as_a_program
    and test_help.test_version check once."""
    argv = shlex.split(command)
    proc = cli_inprocess(*argv[1:], cwd=_scratch(tmp_path))
    assert proc.returncode == 0, f"{command}\n{proc.stderr[-2000:]}"
    if "--json" in argv:
        json.loads(proc.stdout)


def test_readme_example_as_a_program(tmp_path):
    """One example as a user types it: a fresh interpreter, the package's entry point, JSON on stdout."""
    command = next(c for c in readme_commands() if c.startswith("torquebench bridge ") and "--json" in c)
    proc = subprocess.run([sys.executable, "-m", "torquebench", *shlex.split(command)[1:]],
                          cwd=_scratch(tmp_path), capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, f"{command}\n{proc.stderr[-2000:]}"
    json.loads(proc.stdout)


def test_readme_uses_only_in_repo_files():
    """A fresh clone has nothing beside it: no example may reach outside the repository."""
    for command in readme_commands():
        assert "../" not in command, command
