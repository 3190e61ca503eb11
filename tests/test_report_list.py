"""`torquebench report --list`: every report area with a one-line description and its last measured
build time (or "not timed yet"), in text and JSON."""

import json
import subprocess
import sys

from torquebench.commands.report import builders, describe


def test_every_area_is_described_in_one_sentence():
    for area, module in builders().items():
        d = describe(module)
        assert d and not d.startswith("reports/") and d.endswith(".") and len(d) < 300, (area, d)


def test_list_prints_description_and_run_time():
    proc = subprocess.run([sys.executable, "-m", "torquebench", "report", "--list", "--json"],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    rows = json.loads(proc.stdout)["reports"]
    assert {r["area"] for r in rows} == set(builders())
    for r in rows:
        assert r["description"]
        assert r["last_build_s"] is None or r["last_build_s"] > 0
    text = subprocess.run([sys.executable, "-m", "torquebench", "report", "--list"],
                          capture_output=True, text=True, timeout=120).stdout
    assert text.count("run time:") == len(rows)
