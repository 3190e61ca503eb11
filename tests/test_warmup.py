"""The install-time compile (estimator.warmup, called by run.sh) runs every estimator loop without
error: a loop whose arguments changed and a warm-up that was not updated raised there silently,
and the loops then compiled inside the first runs and the test suite (36 CPU-s of a fresh clone's
default suite, measured 2026-11-26)."""

from estimator import compiled, warmup


def test_warm_runs_every_compiled_loop():
    assert compiled.available()                  # numba is a dependency (pyproject.toml)
    assert warmup.warm() is True
