"""Small modules with one job: no source module of the project over about 600 lines (this test
fails past ``MAX_LINES``)."""

from __future__ import annotations

from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("userio", "bridge", "flexure", "calibration", "estimator", "torquebench", "benchmarks")
MAX_LINES = 650


def long_modules(limit: int = MAX_LINES) -> dict[str, int]:
    """{path relative to the checkout: lines} of every ``.py`` of the packages over ``limit``."""
    out = {}
    for pkg in PACKAGES:
        for f in sorted((ROOT / pkg).rglob("*.py")):
            n = len(f.read_text(encoding="utf-8").splitlines())
            if n > limit:
                out[f.relative_to(ROOT).as_posix()] = n
    return out


def test_the_count_sees_long_modules():
    assert "estimator/stream.py" in long_modules(limit=100)


def test_no_module_over_about_600_lines():
    found = long_modules()
    assert not found, f"modules over {MAX_LINES} lines (split them by what they compute): {found}"
