"""CLI contracts: discovered subcommands, --json on every command, exit 2 with one line."""

import json
import subprocess
import sys

import pytest

from torquebench.cli import build_parser, main
from torquebench.io import jsonable
from userio.files import atomic_path, write_text_atomic


def _subcommands():
    parser = build_parser()
    action = next(a for a in parser._actions if a.dest == "command")
    return action.choices


def test_every_subcommand_takes_json():
    commands = _subcommands()
    assert commands, "no subcommands discovered"
    for name, sub in commands.items():
        assert any("--json" in a.option_strings for a in sub._actions), name


def test_unknown_option_exits_2_with_one_line():
    proc = subprocess.run([sys.executable, "-m", "torquebench", "--no-such-flag"],
                          capture_output=True, text=True)
    assert proc.returncode == 2
    assert proc.stdout == "" and len(proc.stderr.strip().splitlines()) == 1


def test_jsonable_maps_nan_to_null_and_numpy_to_python():
    import numpy as np
    out = json.dumps(jsonable({"a": np.float64("nan"), "b": np.arange(2), "c": np.bool_(True)}),
                     allow_nan=False)
    assert json.loads(out) == {"a": None, "b": [0, 1], "c": True}


def test_atomic_write_leaves_original_on_failure(tmp_path):
    target = tmp_path / "cal.json"
    target.write_text("original")
    with pytest.raises(RuntimeError):
        with atomic_path(target) as tmp:
            tmp.write_text("half-written")
            raise RuntimeError("boom")
    assert target.read_text() == "original"
    assert list(tmp_path.iterdir()) == [target]
    write_text_atomic(target, "new")
    assert target.read_text() == "new"
