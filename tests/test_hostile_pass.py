"""The adversarial pass (benchmarks/hostile_pass.py) on a few cases of every class, each a real
`torquebench` process: no traceback, no file changed outside the declared outputs, no runaway,
no control case refused. Slow (a few minutes of subprocesses): `pytest -m slow`."""

import json
import subprocess
import sys

import pytest

from torquebench.io import REPO_ROOT


@pytest.mark.slow
def test_a_small_hostile_pass_is_clean(tmp_path):
    out = tmp_path / "pass.json"
    proc = subprocess.run([sys.executable, str(REPO_ROOT / "benchmarks" / "hostile_pass.py"),
                           "--seed", "7", "--limit", "4", "--timeout", "300", "--json", str(out)],
                          capture_output=True, text=True, timeout=3600)
    assert proc.returncode == 0, proc.stderr[-2000:]
    records = json.loads(out.read_text())["records"]
    bad = [(r["outcome"], r["name"], r["stderr"][-300:]) for r in records
           if r["outcome"] in ("traceback", "data_loss", "runaway", "refused_valid")]
    assert not bad, bad
    assert len({r["class"] for r in records}) >= 5
