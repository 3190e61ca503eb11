"""docs/inputs.md, generated from the schema models: every field of every input file with its
type, unit, default, range and meaning.

    python -m userio.schema.docs            # write docs/inputs.md
    python -m userio.schema.docs --check    # exit 1 if the committed file differs

(tests/test_schema_docs.py checks the committed file equals the generated one.)
"""

from __future__ import annotations

import sys
import types
import typing
from pathlib import Path

import annotated_types as at
from pydantic import BaseModel
from pydantic.fields import FieldInfo
from pydantic_core import PydanticUndefined

from userio.schema.base import LengthCheck, OneOf, RangeCheck

OUT = Path(__file__).resolve().parents[2] / "docs" / "inputs.md"

# unit from a key's suffix, when its physical range does not state one (longest first)
SUFFIX_UNITS = [("_m_per_s2", "m/s²"), ("_kgm2", "kg·m²"), ("_rad_per_s", "rad/s"), ("_per_Nm", "1/(N·m)"),
                ("_V_per_rtHz", "V/√Hz"), ("_Ns_per_m", "N·s/m"), ("_N_per_m", "N/m"), ("_Nm", "N·m"),
                ("_GPa", "GPa"), ("_MPa", "MPa"), ("_ohm", "Ω"), ("_Hz", "Hz"), ("_kg", "kg"),
                ("_mm", "mm"), ("_deg", "deg"), ("_rad", "rad"), ("_V", "V"), ("_K", "K"), ("_N", "N"),
                ("_m", "m"), ("_s", "s"), ("_g", "g")]


def kinds():
    """(title, model, where the file comes from) of every input file kind."""
    from userio.schema.calibration import CalibrationFile
    from userio.schema.design import DesignFile
    from userio.schema.logs import NoiseFile, TimingFile
    from userio.schema.robot import RobotFile, SpatialRobotFile
    from userio.schema.scene import SceneFile
    from userio.schema.sensor import SensorFile
    from userio.schema.spatial_scene import SpatialSceneFile

    out = [("Planar scene", SceneFile, "`run SCENE`, `simulate`, `sweep`, `compare`"),
           ("Planar robot", RobotFile, "`--robot FILE.toml`, a scene's `robot`"),
           ("URDF robot declaration", SpatialRobotFile, "`--robot FILE.toml` naming a URDF"),
           ("Sensor", SensorFile, "`bridge --config`, a scene's `[sensor] file`, a design's `[bridge] sensor`"),
           ("Flexure design", DesignFile, "`flexure DESIGN.toml`, a scene's `[flexure] design`"),
           ("Log timing declaration", TimingFile, "`LOG.timing.toml` beside `LOG.csv`"),
           ("Log noise declaration", NoiseFile, "`LOG.noise.toml` beside `LOG.csv`"),
           ("Calibration", CalibrationFile, "`apply CAL.json`, a scene's `[calibration] file`"),
           ("3-D scene", SpatialSceneFile, "`simulate SCENE.toml` (a scene whose robot is a URDF)")]
    return out


def _unwrap(ann):
    """(core type, optional?, [metadata]) of an annotation: Optional and Annotated peeled off."""
    meta, optional = [], False
    while True:
        origin = typing.get_origin(ann)
        if origin is typing.Annotated:
            ann, *extra = typing.get_args(ann)
            for m in extra:
                meta += list(m.metadata) if isinstance(m, FieldInfo) else [m]
        elif origin in (typing.Union, types.UnionType):
            args = [a for a in typing.get_args(ann) if a is not type(None)]
            optional = optional or len(args) < len(typing.get_args(ann))
            if len(args) != 1:
                return ann, optional, meta
            ann = args[0]
        else:
            return ann, optional, meta


def _model_of(ann):
    core, _, _ = _unwrap(ann)
    if isinstance(core, type) and issubclass(core, BaseModel):
        return core, False
    if typing.get_origin(core) is list:
        inner, _, _ = _unwrap(typing.get_args(core)[0])
        if isinstance(inner, type) and issubclass(inner, BaseModel):
            return inner, True
    return None, False


def vocabularies() -> dict[str, tuple[str, ...]]:
    """The names the vocabulary fields (``OneOf``) accept, from the packages that declare them: a
    scene's ``want`` lists what the stage declarations offer. (The one import of torquebench in
    userio, here in the documentation generator only: the schema itself gets the names passed in.)"""
    from torquebench.stages.registry import scene_outputs

    return {"scene_outputs": scene_outputs()}


_VOCABULARIES: dict = {}              # set by render()


def _type(ann, extra=()) -> str:
    core, _, meta = _unwrap(ann)
    meta = list(extra) + meta
    origin = typing.get_origin(core)
    vocab = next((m for m in _metas(meta) if isinstance(m, OneOf)), None)
    if vocab is not None:
        names = _VOCABULARIES[vocab.vocabulary]
        return "one of " + ", ".join(f"`{v!r}`".replace("'", '"') for v in names)
    if origin is typing.Literal:
        return "one of " + ", ".join(f"`{v!r}`".replace("'", '"') for v in typing.get_args(core))
    if origin is list:
        inner = typing.get_args(core)[0]
        n = next((m.n for m in _metas(meta) if isinstance(m, LengthCheck)), None)
        what = _type(inner)
        word = {"number": "numbers", "integer": "integers", "string": "strings"}.get(what, what)
        return f"list of {n} {word}" if n else f"list of {word}"
    if origin is dict:
        return f"table of {_type(typing.get_args(core)[1])}"
    if origin in (typing.Union, types.UnionType):
        return " or ".join("table" if isinstance(a, type) and issubclass(a, BaseModel) else _type(a)
                           for a in typing.get_args(core))
    return {float: "number", int: "integer", str: "string", bool: "true/false"}.get(core, "any")


def _metas(meta):
    for m in meta:
        yield getattr(m, "func", m)


def _range_unit(ann, key: str, extra=()) -> tuple[str, str]:
    core, _, meta = _unwrap(ann)
    meta = list(extra) + meta
    if typing.get_origin(core) is list:
        _, _, inner = _unwrap(typing.get_args(core)[0])
        meta = meta + inner
    bounds, parts, unit = [], [], ""
    for m in _metas(meta):
        if isinstance(m, RangeCheck):
            parts.append(m.rng.describe() + (" or 0" if m.rng.zero_ok else ""))
            unit = m.rng.unit
        for i, (cls, sym, attr) in enumerate(((at.Gt, ">", "gt"), (at.Ge, "≥", "ge"),
                                              (at.Lt, "<", "lt"), (at.Le, "≤", "le"))):
            if isinstance(m, cls):
                bounds.append((i, f"{sym} {getattr(m, attr):g}"))
    parts = [b for _, b in sorted(bounds)] + parts
    if not unit:
        unit = next((u for s, u in SUFFIX_UNITS if key.endswith(s)), "")
    return "; ".join(parts), unit


def _default(info: FieldInfo) -> str:
    if info.is_required():
        return "required"
    d = info.default
    if d is PydanticUndefined or d is None:
        return "—"
    if isinstance(d, BaseModel):
        return "(table)"
    if isinstance(d, (list, tuple)):
        return "[]" if not d else "[" + ", ".join(f"{x:g}" if isinstance(x, float) else str(x) for x in d) + "]"
    if isinstance(d, bool):
        return "true" if d else "false"
    if isinstance(d, float):
        return f"{d:g}"
    return f'"{d}"' if isinstance(d, str) else str(d)


def _cell(text: str) -> str:
    return str(text).replace("|", "\\|").replace("\n", " ")


def model_tables(model, name: str = "", out=None) -> list[str]:
    """Markdown: one table of ``model``'s keys, then one per nested table (depth first)."""
    out = [] if out is None else out
    rows, nested = [], []
    for field_name, info in model.model_fields.items():
        key = info.alias or field_name
        sub, many = _model_of(info.annotation)
        if sub is not None:
            nested.append((f"{name}.{key}" if name else key, sub, many))
            kind = "[[tables]]" if many else "table"
            rows.append(f"| `{key}` | {kind} | | {_default(info)} | | {_cell(info.description or '')} |")
            continue
        rng, unit = _range_unit(info.annotation, key, info.metadata)
        rows.append(f"| `{key}` | {_cell(_type(info.annotation, info.metadata))} | {_cell(unit)} | {_cell(_default(info))} "
                    f"| {_cell(rng)} | {_cell(info.description or '')} |")
    if name:
        out += ["", f"#### `{name}`" if name.startswith("[[") else f"#### `[{name}]`", ""]
    doc = (model.__doc__ or "").strip().splitlines()
    if name and doc:
        out += [" ".join(line.strip() for line in doc), ""]
    out += ["| key | type | unit | default | range | meaning |", "|---|---|---|---|---|---|", *rows]
    for sub_name, sub, many in nested:
        model_tables(sub, f"[[{sub_name}]]" if many else sub_name, out)
    return out


def render(vocabs: dict | None = None) -> str:
    """docs/inputs.md (``vocabs``: the vocabularies' names, default :func:`vocabularies`)."""
    _VOCABULARIES.clear()
    _VOCABULARIES.update(vocabularies() if vocabs is None else vocabs)
    lines = ["# Input files: every field", "",
             "<!-- generated by `python -m userio.schema.docs` from the models in userio/schema/; "
             "do not edit by hand (tests/test_schema_docs.py) -->", "",
             "Every input file goes through one schema (userio/schema/, pydantic): unknown keys are "
             "refused with the nearest valid key, types are strict (`true` is not a number, `\"3\"` "
             "is not an integer), numbers finite and inside their physical range. A problem ends the "
             "command with exit code 2 and one line, `FILE: [table.]field: problem (did you mean "
             "'x'?)`; entries of lists are numbered from 1 (`link[2].mass_kg`). Units are in the "
             "key names; \"—\" as a default: absent unless given. Rules between fields (a centre "
             "of mass on its link, ENOB ≤ bits, …) are stated in the meanings and in "
             "[input rules](input-rules.md).", ""]
    for title, model, where in kinds():
        doc = " ".join(line.strip() for line in (model.__doc__ or "").strip().splitlines())
        lines += ["", f"## {title}", "", f"{doc} Read from {where}.", ""]
        lines += model_tables(model)
    return "\n".join(lines).rstrip() + "\n"


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    text = render()
    if "--check" in argv:
        if not OUT.is_file() or OUT.read_text(encoding="utf-8") != text:
            print(f"{OUT} is out of date: run python -m userio.schema.docs", file=sys.stderr)
            return 1
        return 0
    OUT.write_text(text, encoding="utf-8")
    print(f"wrote {OUT}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
