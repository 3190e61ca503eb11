"""A stage's cache key: SHA-256 of its name, its canonical inputs (``Stage.params``), the keys of
the stages it consumes and the hash of its code (torquebench.stages.codedeps: derived from the
import graph). Equal keys ⇔ the same computation; the helpers below make scene values exact,
JSON-able data for that hash."""

from __future__ import annotations

import hashlib
import json
import os
import stat
from pathlib import Path

import numpy as np

from torquebench.stages import codedeps


def stage_key(stage, params: dict, upstream: list[str]) -> str:
    """The cache key of one run of ``stage``."""
    blob = json.dumps({"stage": stage.name, "params": params, "up": upstream,
                       "code": codedeps.code_version(stage)}, sort_keys=True, default=str)
    return hashlib.sha256(blob.encode()).hexdigest()[:32]


def canon(x):
    """A scene value as exact, JSON-able data for a cache key: dataclasses field by field, arrays
    by dtype, shape and a hash of their bytes, floats by ``repr`` (round-trip exact). ``repr`` of a
    numpy array keeps 8 digits and elides long arrays, so two different inputs could share a key."""
    import dataclasses

    if dataclasses.is_dataclass(x) and not isinstance(x, type):
        return {"type": type(x).__name__,
                **{f.name: canon(getattr(x, f.name)) for f in dataclasses.fields(x)}}
    if isinstance(x, np.ndarray):
        a = np.ascontiguousarray(x)
        return {"dtype": a.dtype.str, "shape": list(a.shape),
                "sha256": hashlib.sha256(a.tobytes()).hexdigest()}
    if isinstance(x, dict):
        return {str(k): canon(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [canon(v) for v in x]
    if isinstance(x, np.generic):
        return canon(x.item())
    if isinstance(x, float):
        return repr(x)
    if x is None or isinstance(x, (str, int, bool)):
        return x
    return repr(x)


def file_hash(p):
    """SHA-256 of a file's bytes (None: no file; an unreadable file keys as such and its reader
    reports it in one line when the stage runs)."""
    if not p:
        return None
    try:
        if not stat.S_ISREG(os.stat(p).st_mode):        # a device or FIFO: never read to its end
            return f"not a regular file: {p}"
        h = hashlib.sha256()
        with open(p, "rb") as f:
            for block in iter(lambda: f.read(1 << 20), b""):
                h.update(block)
        return h.hexdigest()
    except OSError as exc:
        return f"unreadable: {p}: {type(exc).__name__}"


def design_hash(p):
    """Hash of a flexure design file and of the files it names (``[geometry] file``, the STL or
    STEP part, and ``[bridge] sensor``, paths relative to the design): editing the part re-runs
    the FEM as editing the design does. The design is parsed here only for those two names;
    ``load_design`` validates it when the stage runs."""
    import tomllib

    key = {"design": file_hash(p)}
    try:
        raw = tomllib.loads(Path(p).read_text())
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError):
        return key                                 # the stage's own reader names the problem
    for table, field in (("geometry", "file"), ("bridge", "sensor")):
        name = raw.get(table, {}).get(field) if isinstance(raw.get(table), dict) else None
        if isinstance(name, str):
            key[f"{table}.{field}"] = file_hash(Path(p).parent / name)
    return key

