"""A script of benchmarks/ loaded as a module, for the tests that call into it."""

import importlib.util
import sys
from pathlib import Path

BENCHMARKS = Path(__file__).resolve().parents[1] / "benchmarks"


def benchmark_module(name: str, as_name: str | None = None):
    """benchmarks/``name``.py executed as a module (``as_name``, default ``_bench_<name>``); its siblings
    importable while it loads (a script that imports a helper beside it)."""
    spec = importlib.util.spec_from_file_location(as_name or f"_bench_{name}", BENCHMARKS / f"{name}.py")
    mod = importlib.util.module_from_spec(spec)
    sys.path.insert(0, str(BENCHMARKS))
    try:
        spec.loader.exec_module(mod)
    finally:
        sys.path.remove(str(BENCHMARKS))
    return mod
