"""`torquebench report --list`: every report area with a one-line description and its last measured
build time (or "not timed yet"), in text and JSON."""

import json

from torquebench.commands.report import builders, describe


def test_every_area_is_described_in_one_sentence():
    for area, module in builders().items():
        d = describe(module)
        assert d and not d.startswith("reports/") and d.endswith(".") and len(d) < 300, (area, d)


def test_list_prints_description_and_run_time(cli_inprocess):
    proc = cli_inprocess("report", "--list", "--json")
    assert proc.returncode == 0, proc.stderr
    rows = json.loads(proc.stdout)["reports"]
    assert {r["area"] for r in rows} == set(builders())
    for r in rows:
        assert r["description"]
        assert r["last_build_s"] is None or r["last_build_s"] > 0
    text = cli_inprocess("report", "--list").stdout
    assert text.count("run time:") == len(rows)


def test_every_build_of_the_shipped_reports_records_each_areas_time(tmp_path, monkeypatch):
    """`report` building into the repository's reports/ records each built area's time and date
    in build_times.json (what `--list` shows), keeping the areas it did not build."""
    import argparse
    import sys as _sys
    import types

    import torquebench.io as tio
    from torquebench.commands import report

    (tmp_path / "reports").mkdir()
    (tmp_path / "reports" / report.TIMES_FILE).write_text(json.dumps({"old": {"s": 3.0, "date": "2026-01-01"}}))
    monkeypatch.setattr(tio, "REPO_ROOT", tmp_path)
    for name in ("fake_a", "fake_b"):
        mod = types.ModuleType(f"fakereports.{name}")

        def build(out_dir, _n=name):
            p = out_dir / f"{_n}.md"
            p.write_text(f"# {_n}\n\n**Headline:** {_n} built in a test run here\n")
            return [p]

        mod.build = build
        monkeypatch.setitem(_sys.modules, f"fakereports.{name}", mod)
    areas = {"fake_a": "fakereports.fake_a", "fake_b": "fakereports.fake_b"}
    args = argparse.Namespace(json=True)
    assert report._build(args, areas, ["fake_a", "fake_b"], tmp_path / "reports") == 0
    times = report.recorded_times(tmp_path / "reports")
    assert set(times) == {"old", "fake_a", "fake_b"} and times["old"]["s"] == 3.0
    assert all(times[a]["s"] >= 0 and len(times[a]["date"]) == 10 for a in ("fake_a", "fake_b"))
    # and the machine it was timed on: the 1-minute load and the cores (a time means little without)
    assert all(times[a]["load_1min"] >= 0 and times[a]["cores"] >= 1 for a in ("fake_a", "fake_b"))
    monkeypatch.setattr(report, "recorded_times", lambda d: {"bridge": times["fake_a"]})
    row = next(r for r in report._listing(builders()) if r["area"] == "bridge")
    assert row["last_build_load_1min"] == times["fake_a"]["load_1min"]
    assert f"on {times['fake_a']['cores']} cores" in report._machine(row)


def test_shipped_build_times_name_only_real_areas():
    from torquebench.commands.report import recorded_times
    from torquebench.io import REPO_ROOT

    times = recorded_times(REPO_ROOT / "reports")
    assert times and set(times) <= set(builders())
    assert all(v["s"] > 0 for v in times.values())
