"""The model base, the field helpers and the one error formatter of every input file.

A file kind is a :class:`Model` (pydantic v2): unknown keys are refused with the nearest valid key,
types are strict (``true`` is not a number, ``"3"`` is not an integer), numbers finite, and each
physical quantity carries its :class:`userio.ranges.Range` (unit, bounds, what a value outside
usually means), checked here and printed by ``userio.schema.docs``. :func:`parse` turns the first
problem into ONE line::

    FILE: [table.]field: problem (did you mean 'x'?)

Lists of tables and vector elements are numbered from 1 (``link[2].mass_kg``, ``ft_noise[3]``).
"""

from __future__ import annotations

import os
from typing import Annotated

# no third-party pydantic plugins: finding them scans every installed package's entry points
# (~30–150 ms at the first model); a user who needs one can set the variable to ""
os.environ.setdefault("PYDANTIC_DISABLE_PLUGINS", "__all__")

from pydantic import AfterValidator, BaseModel, ConfigDict, Field, ValidationError, model_validator  # noqa: E402
from pydantic_core import PydanticCustomError  # noqa: E402

from userio.errors import InputError, nearest  # noqa: E402
from userio.ranges import Range  # noqa: E402

__all__ = ["Model", "Field", "RangeCheck", "num", "integer", "vector", "fail", "parse", "Range"]


class Model(BaseModel):
    """One table of an input file: known keys only, strict types, finite numbers."""

    model_config = ConfigDict(extra="forbid", strict=True, allow_inf_nan=False, frozen=True,
                              protected_namespaces=(), arbitrary_types_allowed=True)

    @model_validator(mode="before")
    @classmethod
    def _known_keys(cls, data):
        if isinstance(data, dict):
            allowed = [f.alias or name for name, f in cls.model_fields.items()]
            extra = sorted(str(k) for k in data if k not in allowed)
            if extra:
                hint = nearest(extra[0], allowed)
                listed = "" if hint else f" (allowed: {', '.join(sorted(allowed))})"
                raise PydanticCustomError("unknown_field", "unknown field{hint}",
                                          {"key": extra[0], "hint": hint + listed})
        return data

    def given(self, name: str) -> bool:
        """Whether the file set ``name`` (rather than taking its default)."""
        return name in self.model_fields_set


class RangeCheck:
    """The value inside its physical range (``zero_ok`` of the Range: 0 switches a feature off)."""

    def __init__(self, rng: Range):
        self.rng = rng

    def __call__(self, v):
        if v is not None:
            why = self.rng.problem(float(v))
            if why:
                raise PydanticCustomError("range", "{why}", {"why": why})
        return v


def _annotated(base, rng: Range | None, constraints: dict):
    meta = []
    constraints = {k: v for k, v in constraints.items() if v is not None}
    if constraints:
        meta.append(Field(**constraints))
    if rng is not None:
        meta.append(AfterValidator(RangeCheck(rng)))
    return Annotated[tuple([base, *meta])] if meta else base


def num(rng: Range | None = None, *, gt=None, ge=None, lt=None, le=None):
    """A finite float (an integer in the file is fine) with optional bounds and physical range."""
    return _annotated(float, rng, dict(gt=gt, ge=ge, lt=lt, le=le))


def integer(rng: Range | None = None, *, ge=None, le=None):
    """An integer (``3.0`` and ``true`` are refused)."""
    return _annotated(int, rng, dict(ge=ge, le=le))


class LengthCheck:
    """A list of exactly ``n`` entries."""

    def __init__(self, n: int):
        self.n = n

    def __call__(self, v):
        if len(v) != self.n:
            raise PydanticCustomError("range", "expected {n} numbers, got {got}",
                                      {"n": self.n, "got": len(v)})
        return v


def vector(length: int | None = None, rng: Range | None = None, *, ge=None, gt=None, le=None):
    """A list of finite numbers (``length`` of them when given, else at least one)."""
    elem = num(rng, ge=ge, gt=gt, le=le)
    if length is not None:
        return Annotated[list[elem], AfterValidator(LengthCheck(length))]
    return Annotated[list[elem], Field(min_length=1)]


class OneOf:
    """A string that must be one of the names a *vocabulary* offers, where the package that owns
    those names declares them: the schema lists none itself. The reader passes them in the
    validation context, ``parse(model, data, src, context={vocabulary: names})``; e.g. a scene's
    ``[outputs] want`` takes what the stage declarations offer (torquebench.stages), so a new
    stage is declared in one place. The documentation lists them through the same vocabulary."""

    def __init__(self, vocabulary: str):
        self.vocabulary = vocabulary

    def __call__(self, v: str, info):
        names = (info.context or {}).get(self.vocabulary)
        if names is None:
            raise TypeError(f"validating a {self.vocabulary!r} name needs context="
                            f"{{{self.vocabulary!r}: names}} (a bug in the reader)")
        if v not in names:
            expected = ", ".join(repr(n) for n in names[:-1]) + f" or {names[-1]!r}" if len(names) > 1 \
                else repr(names[0]) if names else "(nothing is offered)"
            raise PydanticCustomError("literal_error", "Input should be {expected}", {"expected": expected})
        return v


def one_of(vocabulary: str):
    """A string field checked against a vocabulary given at validation time (:class:`OneOf`)."""
    return Annotated[str, AfterValidator(OneOf(vocabulary))]


def fail(field: str, msg: str):
    """The error of a cross-field check, naming ``field`` (relative to the model being checked)."""
    return PydanticCustomError("field", "{msg}", {"field": field, "msg": msg})


# --------------------------------------------------------------------------- one error line
_TAGS = {"str", "float", "int", "bool", "list", "dict"}


def _model_names(cls=None) -> set[str]:
    cls = cls or Model
    out = {cls.__name__}
    for sub in cls.__subclasses__():
        out |= _model_names(sub)
    return out


def _is_tag(part) -> bool:
    return isinstance(part, str) and (part in _TAGS or part in _model_names() or "[" in part)


def _where(loc) -> str:
    """``link[2].mass_kg`` from pydantic's loc; the branch tags of a union ("str", a model's
    class name, "list[float]") are not keys and are left out."""
    out = ""
    for part in loc:
        if _is_tag(part):
            continue
        if isinstance(part, int):
            out += f"[{part + 1}]"
        elif part:
            out += ("." if out else "") + str(part)
    return out


def _got(v) -> str:
    return repr(v) if not isinstance(v, dict) else "a table"


_BOUND = {"greater_than": ">", "greater_than_equal": "≥", "less_than": "<", "less_than_equal": "≤"}


def _problem(e: dict) -> str:
    t, ctx, v = e["type"], e.get("ctx") or {}, e.get("input")
    if t in ("unknown_field", "range", "field"):
        return e["msg"]
    if t == "missing":
        return "missing field"
    if t in ("float_type", "float_parsing", "finite_number"):
        return f"expected a finite number, got {_got(v)}"
    if t in ("int_type", "int_parsing", "int_from_float"):
        return f"expected an integer, got {_got(v)}"
    if t == "string_type":
        return f"expected a string, got {_got(v)}"
    if t == "bool_type":
        return f"expected true or false, got {_got(v)}"
    if t in ("model_type", "dict_type", "model_attributes_type"):
        return f"expected a table, got {type(v).__name__}"
    if t == "list_type":
        return f"expected a list, got {_got(v)}"
    if t in ("too_short", "too_long"):
        lo, hi = ctx.get("min_length"), ctx.get("max_length")
        n = ctx.get("actual_length")
        want = f"{lo}" if lo == hi else f"at least {lo}" if t == "too_short" else f"at most {hi}"
        return f"expected {want} entries, got {n}"
    if t in _BOUND:
        bound = next(iter(ctx.values()))
        return f"must be {_BOUND[t]} {bound:g}, got {v!r}"
    if t == "literal_error":
        return f"must be {ctx.get('expected')}, got {v!r}{nearest(v, _literals(ctx))}"
    if t == "value_error":
        return str(ctx.get("error", e["msg"]))
    return e["msg"]


def _literals(ctx) -> list[str]:
    return [s.strip(" '") for s in str(ctx.get("expected", "")).replace(" or ", ",").split(",")]


def _line(e: dict) -> str:
    ctx = e.get("ctx") or {}
    where = _where(e["loc"])
    extra = ctx.get("key") if e["type"] == "unknown_field" else ctx.get("field") if e["type"] == "field" else None
    if extra is not None:
        where = f"{where}.{extra}" if where else str(extra)
    return f"{where}: {_problem(e)}" if where else _problem(e)


_TYPE_ERRORS = {"string_type", "float_type", "int_type", "bool_type", "model_type", "dict_type",
                "list_type", "model_attributes_type"}


def _first(errors: list[dict]) -> dict:
    """The first problem; where it is one branch of a union (a string or a table) refusing the
    value's type, the problem another branch found inside the value, if any."""
    e = errors[0]
    if e["type"] in _TYPE_ERRORS and any(_is_tag(p) for p in e["loc"]):
        key = [p for p in e["loc"] if not _is_tag(p)]
        for other in errors[1:]:
            if [p for p in other["loc"] if not _is_tag(p)][:len(key)] == key and \
                    other["type"] not in _TYPE_ERRORS:
                return other
    return e


def message(exc: ValidationError) -> str:
    """The first problem of a ValidationError as ``[table.]field: problem``."""
    return _line(_first(exc.errors(include_url=False)))


def parse(model: type[Model], data, source, context: dict | None = None) -> Model:
    """``data`` (a parsed file) validated as ``model`` (``context``: what its validators need to
    know beyond the file, e.g. a log's channel names); InputError ``SOURCE: field: problem``."""
    try:
        return model.model_validate(data, context=context)
    except ValidationError as exc:
        raise InputError(f"{source}: {message(exc)}") from None
