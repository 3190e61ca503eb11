"""Errors a user can fix (bad files, bad parameters), and the checks that raise them.

The CLI turns an `InputError` into exit code 2 and its message on one line of stderr, so the
message must name the file, line, column or field and say what is wrong.
"""

from __future__ import annotations

import math


class InputError(ValueError):
    """Bad user input (file, parameter); the message names where and what."""


def finite(value, name: str, *, positive: bool = False, nonneg: bool = False,
           lo: float | None = None, hi: float | None = None) -> float:
    """``value`` as a float that is finite (and > 0, ≥ 0, or in [lo, hi] when asked).

    Infinity and NaN never pass: ``inf > 0`` is true, so a bare ``> 0`` check is not enough.
    """
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise InputError(f"{name}: expected a finite number, got {value!r}") from None
    if isinstance(value, bool) or not math.isfinite(v):
        raise InputError(f"{name}: expected a finite number, got {value!r}")
    if positive and v <= 0:
        raise InputError(f"{name}: must be > 0, got {value!r}")
    if nonneg and v < 0:
        raise InputError(f"{name}: must be ≥ 0, got {value!r}")
    if (lo is not None and v < lo) or (hi is not None and v > hi):
        if lo is None:
            raise InputError(f"{name}: must be ≤ {hi:g}, got {value!r}")
        if hi is None:
            raise InputError(f"{name}: must be ≥ {lo:g}, got {value!r}")
        raise InputError(f"{name}: must lie in [{lo:g}, {hi:g}], got {value!r}")
    return v


def seed(value, name: str = "--seed"):
    """A random seed: None or an integer in [0, 2**63) (numpy refuses negative seeds)."""
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value < 2 ** 63:
        raise InputError(f"{name}: must be an integer in [0, 2^63), got {value!r}")
    return value


class CallbackInterrupt:
    """Ctrl-C inside a Python callback that C code calls (gmsh's mesh-size callback): ctypes would
    print the KeyboardInterrupt with a traceback and swallow it, and the C code would carry on or
    fail with an unrelated error. ``wrap(fn, abort_value)`` records the interrupt and returns
    ``abort_value`` (which makes the C code stop) from then on; ``check()``, called once the C call
    has returned or failed, re-raises it as a plain KeyboardInterrupt.

    From ``wrap`` to ``check`` SIGINT only sets the flag (a handler that raises nothing): a
    KeyboardInterrupt raised by Python's own handler could land in the C library's ctypes wrapper
    around the callback, outside ``fn``, where nothing catches it. A second Ctrl-C raises at once."""

    def __init__(self):
        self.hit = False
        self._previous = None

    def _on_sigint(self, signum, frame):
        if self.hit:                      # pressed again: do not wait for the C code
            self._restore()
            raise KeyboardInterrupt
        self.hit = True

    def _install(self):
        import signal
        import threading

        if threading.current_thread() is not threading.main_thread():
            return
        current = signal.getsignal(signal.SIGINT)
        if getattr(current, "__self__", None) is not self:
            self._previous = current
            signal.signal(signal.SIGINT, self._on_sigint)

    def _restore(self):
        import signal

        if self._previous is not None:
            try:
                signal.signal(signal.SIGINT, self._previous)
            except (ValueError, OSError):          # not the main thread
                return
            self._previous = None

    def wrap(self, fn, abort_value):
        self._install()

        def guarded(*args):
            if self.hit:
                return abort_value
            try:
                return fn(*args)
            except KeyboardInterrupt:
                self.hit = True
                return abort_value
        return guarded

    def check(self) -> None:
        self._restore()
        if self.hit:
            self.hit = False
            raise KeyboardInterrupt


def nearest(key: str, allowed) -> str:
    """`` (did you mean 'x'?)`` for the closest allowed key, or ``""``."""
    import difflib

    close = difflib.get_close_matches(str(key), sorted(map(str, allowed)), n=1, cutoff=0.6)
    return f" (did you mean {close[0]!r}?)" if close else ""
