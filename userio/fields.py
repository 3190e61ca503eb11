"""The older typed readers of a parsed TOML table, used only by the planar scene reader
(torquebench/scenes.py) until scenes move onto the one schema layer (userio.schema, which every
other input file goes through)::

    f = Fields(path)
    f.known(table, {"kp", "kd"}, "controller")          # unknown key → error with the nearest valid key
    kp = f.number(table, "kp", "controller", 500.0, nonneg=True)
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from userio.errors import InputError, nearest  # noqa: F401  (scenes.py imports nearest from here)
from userio.ranges import Range, check_ranges, field_range, ranged  # noqa: F401  (moved)


def _interval(lo, hi, positive: bool = False) -> str:
    """'[lo, hi]', '(0, hi]', '[lo, ∞)' for a message."""
    left = f"[{lo:g}" if lo is not None else ("(0" if positive else "(−∞")
    right = f"{hi:g}]" if hi is not None else "∞)"
    return f"{left}, {right}"


def _dotted(where: str, key: str) -> str:
    return f"{where}.{key}" if where else key


class Fields:
    """Typed readers for the fields of one TOML file."""

    def __init__(self, path: str | Path):
        self.path = Path(path)

    def err(self, where: str, msg: str) -> InputError:
        return InputError(f"{self.path}: {where}: {msg}")

    def table(self, data: dict, key: str, where: str = "", required=False) -> dict:
        value = data.get(key, None)
        if value is None:
            if required:
                raise self.err(where + key, "missing table")
            return {}
        if not isinstance(value, dict):
            raise self.err(where + key, f"expected a table, got {type(value).__name__}")
        return value

    def known(self, table: dict, allowed: set, where: str):
        extra = sorted(set(table) - set(allowed))
        if extra:
            raise self.err(_dotted(where, extra[0]),
                           f"unknown field{nearest(extra[0], allowed)} "
                           f"(allowed: {', '.join(sorted(allowed))})")

    def number(self, table, key, where, default=None, *, positive=False, nonneg=False,
               lo=None, hi=None) -> float:
        name = _dotted(where, key)
        if key not in table:
            if default is None:
                raise self.err(name, "missing field")
            return float(default)
        v = table[key]
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            raise self.err(name, f"expected a finite number, got {v!r}")
        if positive and v <= 0:
            raise self.err(name, f"must be > 0, got {v}")
        if nonneg and v < 0:
            raise self.err(name, f"must be ≥ 0, got {v}")
        if lo is not None and v < lo or hi is not None and v > hi:
            raise self.err(name, f"must lie in {_interval(lo, hi, positive)}, got {v:g}")
        return float(v)

    def integer(self, table, key, where, default=None, *, lo=None, hi=None) -> int:
        name = _dotted(where, key)
        if key not in table:
            if default is None:
                raise self.err(name, "missing field")
            return int(default)
        v = table[key]
        if isinstance(v, bool) or not isinstance(v, int):
            raise self.err(name, f"expected an integer, got {v!r}")
        if lo is not None and v < lo or hi is not None and v > hi:
            raise self.err(name, f"must lie in {_interval(lo, hi)}, got {v}")
        return v

    def string(self, table, key, where, default=None) -> str:
        name = _dotted(where, key)
        if key not in table:
            if default is None:
                raise self.err(name, "missing field")
            return default
        v = table[key]
        if not isinstance(v, str):
            raise self.err(name, f"expected a string, got {v!r}")
        return v

    def boolean(self, table, key, where, default=None) -> bool:
        name = _dotted(where, key)
        if key not in table:
            if default is None:
                raise self.err(name, "missing field")
            return bool(default)
        v = table[key]
        if not isinstance(v, bool):
            raise self.err(name, f"expected true or false, got {v!r}")
        return v

    def vector(self, table, key, where, length=None, default=None, *, nonneg=False,
               positive=False):
        name = _dotted(where, key)
        if key not in table:
            if default is None:
                raise self.err(name, "missing field")
            return np.asarray(default, float)
        v = table[key]
        if (not isinstance(v, list) or not v
                or not all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in v)):
            raise self.err(name, f"expected a list of numbers, got {v!r}")
        arr = np.asarray(v, float)
        if length is not None and arr.size != length:
            raise self.err(name, f"expected {length} numbers, got {arr.size}")
        if not np.all(np.isfinite(arr)):
            raise self.err(name, f"values must be finite, got {v}")
        if nonneg and np.any(arr < 0):
            raise self.err(name, f"values must be ≥ 0, got {v}")
        if positive and np.any(arr <= 0):
            raise self.err(name, f"values must be > 0, got {v}")
        return arr

    def ranges(self, obj, where: str, keys: dict | None = None):
        """:func:`check_ranges` with the error naming this file; returns ``obj``."""
        try:
            check_ranges(obj, where, keys)
        except InputError as exc:
            raise InputError(f"{self.path}: {exc}") from None
        return obj

    def choice(self, table, key, where, options, default):
        v = table.get(key, default)
        if v not in options:
            raise self.err(_dotted(where, key),
                           f"must be one of {', '.join(map(str, options))}, got {v!r}")
        return v
