"""The switch of the estimator's compiled loops (numba) and their lazy loader.

A module that speeds a function up with numba keeps the loop beside that function: the loop as
plain Python over arrays (``_name_py``), compiled on first use by a ``Loops`` loader, with the
numpy form it replaces kept as the reference it is tested against. Without numba, or with
``ENABLED = False`` (tests and benchmarks compare the two forms), ``available()`` is False and
every caller takes the numpy form. Each sample is computed on its own in every loop, so results
do not depend on how a log is cut into chunks. ``estimator.warmup`` compiles them all once.
"""

from __future__ import annotations

ENABLED = True                  # False: the numpy forms everywhere (tests compare the two)
_NUMBA: bool | None = None


def _numba_importable() -> bool:
    global _NUMBA
    if _NUMBA is None:
        try:
            import numba  # noqa: F401
        except ImportError:
            _NUMBA = False
        else:
            _NUMBA = True
    return _NUMBA


def available() -> bool:
    """True when the compiled loops are used: numba is installed and ``ENABLED``."""
    return ENABLED and _numba_importable()


def jit(fn, **options):
    """``fn`` compiled by numba: no-Python mode, machine code cached beside its module, the GIL
    released, numpy's floating-point error model (x/0 → ±inf or nan, not an exception)."""
    from numba import njit

    return njit(cache=True, nogil=True, error_model="numpy", **options)(fn)


class Loops:
    """A module's compiled loops, built on first use: ``build()`` → {name: compiled function}."""

    def __init__(self, build):
        self._build = build
        self._loops = None

    def get(self) -> dict | None:
        """The compiled loops, or None without numba or with ``ENABLED`` False."""
        if not available():
            return None
        if self._loops is None:
            self._loops = self._build()
        return self._loops
