"""The tutorials (docs/tutorials/*.md) run as written.

Every fenced ```bash and ```python block of a tutorial runs, in order, in a fresh scratch directory
that holds a copy of the repository's inputs (examples/, scenes/, robots/, calibration/data/) and
nothing else, as a newcomer's clone would: bash blocks through ``bash -e`` with the venv's
``torquebench`` first on PATH, python blocks in one namespace per tutorial. Any non-zero exit or
exception fails. A block preceded by ``<!-- skip: REASON -->`` is not run (used only for the
live-serial ``acquire`` step, which needs hardware); the copy is checked to leave the repository's
own files untouched.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
TUTORIALS = ROOT / "docs" / "tutorials"
INPUTS = ("examples", "scenes", "designs", "sensors", "robots", "calibration/data")
BLOCK = re.compile(r"(?:<!--\s*skip:(?P<skip>[^>]*)-->\s*\n)?```(?P<lang>bash|python)[^\n]*\n(?P<code>.*?)^```",
                   flags=re.S | re.M)


def tutorial_files() -> list[Path]:
    return sorted(p for p in TUTORIALS.glob("*.md") if p.name != "index.md")


def blocks(path: Path) -> list[tuple[str, str, str | None]]:
    """(language, code, skip reason or None) of every fenced bash/python block, in order."""
    text = path.read_text(encoding="utf-8")
    return [(m["lang"], m["code"], m["skip"].strip() if m["skip"] else None) for m in BLOCK.finditer(text)]


def test_there_is_one_tutorial_per_job_and_the_index_links_them():
    files = tutorial_files()
    assert len(files) >= 3, files
    index = (TUTORIALS / "index.md").read_text(encoding="utf-8")
    for f in files:
        assert f"({f.name})" in index, f.name
        assert any(lang == "bash" for lang, _, _ in blocks(f)), f.name


def test_skips_are_only_for_hardware():
    for f in tutorial_files():
        for lang, code, skip in blocks(f):
            if skip is not None:
                assert "hardware" in skip and "acquire" in code, (f.name, code)


def test_the_block_parser_reads_skips_and_languages():
    text = "x\n<!-- skip: needs hardware -->\n```bash\nacquire\n```\n\n```python\nprint(1)\n```\n```console\n$ no\n```\n"
    found = [(m["lang"], m["code"], m["skip"]) for m in BLOCK.finditer(text)]
    assert found == [("bash", "acquire\n", " needs hardware "), ("python", "print(1)\n", None)]


@pytest.mark.slow
@pytest.mark.parametrize("tutorial", [p.name for p in tutorial_files()])
def test_tutorial_runs(tutorial, tmp_path, monkeypatch):
    work = tmp_path / "clone"
    for name in INPUTS:
        shutil.copytree(ROOT / name, work / name)
    env = {**os.environ, "MPLBACKEND": "Agg", "PYVISTA_OFF_SCREEN": "true",
           "PATH": f"{Path(sys.executable).parent}{os.pathsep}{os.environ.get('PATH', '')}"}
    monkeypatch.chdir(work)
    monkeypatch.setenv("MPLBACKEND", "Agg")
    namespace: dict = {"__name__": "__tutorial__"}
    ran = 0
    for i, (lang, code, skip) in enumerate(blocks(TUTORIALS / tutorial)):
        if skip is not None:
            continue
        if lang == "bash":
            proc = subprocess.run(["bash", "-e", "-c", code], cwd=work, env=env, capture_output=True,
                                  text=True, timeout=900)
            assert proc.returncode == 0, (f"{tutorial} block {i} (bash) exited {proc.returncode}:\n{code}\n"
                                          f"--- stdout\n{proc.stdout[-2000:]}\n--- stderr\n{proc.stderr[-3000:]}")
        else:
            exec(compile(code, f"{tutorial}:block{i}", "exec"), namespace)
        ran += 1
    assert ran > 0
