"""Physical ranges are declared once, next to the field they bound, as a :class:`Range` in the
dataclass field's metadata (``ranged(default, Range(...))``) or beside a CLI option; the checks
(``Range.check``, ``check_ranges``) read them from there. The declaration is
data (lo, hi, unit, hints): the file schemas (userio.schema) attach the same objects to their
fields, check them there and print them in the generated field documentation.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from userio.errors import InputError


@dataclasses.dataclass(frozen=True)
class Range:
    """The physical range of a quantity: lo ≤ v ≤ hi (``lo_open``: lo < v), in ``unit``.

    ``low`` / ``high``: what a value below / above usually means (a unit typed wrong: "mm typed
    as m?"), added to the message. ``zero_ok``: 0 is also allowed (an "off" value, e.g. no
    encoder quantization) even when lo > 0."""

    lo: float | None = None
    hi: float | None = None
    unit: str = ""
    low: str = ""
    high: str = ""
    lo_open: bool = False
    zero_ok: bool = False

    def describe(self) -> str:
        u = f" {self.unit}" if self.unit else ""
        if self.lo is not None and self.hi is not None:
            return f"{'(' if self.lo_open else '['}{self.lo:g}, {self.hi:g}]{u}"
        if self.lo is not None:
            return f"{'>' if self.lo_open else '≥'} {self.lo:g}{u}"
        return f"≤ {self.hi:g}{u}"

    def problem(self, v: float) -> str | None:
        """None if ``v`` (a finite float) lies in the range, else the reason."""
        if self.zero_ok and v == 0:
            return None
        below = self.lo is not None and (v < self.lo or (self.lo_open and v == self.lo))
        above = self.hi is not None and v > self.hi
        if not (below or above):
            return None
        u = f" {self.unit}" if self.unit else ""
        hint = self.low if below else self.high
        return (f"{v:g}{u} is outside the physical range {self.describe()}"
                + (" (or 0)" if self.zero_ok else "") + (f": {hint}" if hint else ""))

    def check(self, value, name: str) -> float:
        """``value`` as a finite float inside the range, else InputError naming ``name``."""
        from userio.errors import finite

        v = finite(value, name)
        why = self.problem(v)
        if why:
            raise InputError(f"{name}: {why}")
        return v

    def check_all(self, values, name: str) -> np.ndarray:
        """Every element of ``values`` (finite) inside the range."""
        arr = np.atleast_1d(np.asarray(values, float))
        if not np.all(np.isfinite(arr)):
            raise InputError(f"{name}: values must be finite, got {arr.tolist()}")
        for x in arr.ravel():
            why = self.problem(float(x))
            if why:
                raise InputError(f"{name}: {why}")
        return arr


def ranged(default, rng: Range, **kw):
    """A dataclass field with its physical range: ``kp: float = ranged(500.0, Range(0, 1e7, "N·m/rad"))``."""
    if isinstance(default, (list, dict, np.ndarray)):
        return dataclasses.field(default_factory=lambda: np.array(default, float),
                                 metadata={"range": rng}, **kw)
    return dataclasses.field(default=default, metadata={"range": rng}, **kw)


def field_range(cls, name: str) -> Range | None:
    """The Range declared on dataclass ``cls``'s field ``name`` (None if it has none)."""
    for f in dataclasses.fields(cls):
        if f.name == name:
            return f.metadata.get("range")
    return None


def check_ranges(obj, prefix: str = "", keys: dict | None = None) -> None:
    """Check every field of dataclass instance ``obj`` that declares a Range (None values skipped);
    the message names ``prefix.key`` (``keys`` maps a field name to its file key if they differ)."""
    for f in dataclasses.fields(obj):
        rng = f.metadata.get("range")
        value = getattr(obj, f.name)
        if rng is None or value is None:
            continue
        key = (keys or {}).get(f.name, f.name)
        name = f"{prefix}.{key}" if prefix else key
        if np.ndim(value):
            rng.check_all(value, name)
        else:
            rng.check(value, name)
