"""File I/O shared by the commands: atomic writes, TOML and JSON output.

Contracts (DESIGN.md): files the tool writes appear whole or not at all (temp file + rename);
``--json`` prints exactly one JSON object on stdout, numbers in SI units, NaN as null.
"""

from __future__ import annotations

import json
import math
import os
import sys
import tempfile
import tomllib
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from torquebench.errors import InputError

REPO_ROOT = Path(__file__).resolve().parents[1]


def shipped(kind: str, name: str) -> Path:
    """Path of a file shipped with the project, e.g. ``shipped("robots", "paper_leg.toml")``."""
    return REPO_ROOT / kind / name


@contextmanager
def atomic_path(path: str | os.PathLike, *, overwrite: bool = True):
    """Yield a temporary path beside ``path``; rename it onto ``path`` only if the block succeeds.

    With ``overwrite=False`` an existing ``path`` is an InputError (nothing is touched).
    """
    path = Path(path)
    if not overwrite and path.exists():
        raise InputError(f"{path}: exists; refusing to overwrite it")
    if not path.parent.exists():
        raise InputError(f"{path}: directory {path.parent} does not exist")
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=path.suffix, dir=path.parent)
    umask = os.umask(0)
    os.umask(umask)
    os.fchmod(fd, 0o666 & ~umask)      # mkstemp makes 0600; written files get the usual mode
    os.close(fd)
    try:
        yield Path(tmp)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def write_text_atomic(path: str | os.PathLike, text: str, *, overwrite: bool = True) -> Path:
    """Write ``text`` to ``path`` atomically (temp file + fsync + rename)."""
    with atomic_path(path, overwrite=overwrite) as tmp:
        with open(tmp, "w", encoding="utf-8") as fh:
            fh.write(text)
            fh.flush()
            os.fsync(fh.fileno())
    return Path(path)


def read_toml(path: str | os.PathLike) -> dict:
    """Parse a TOML file; a syntax error becomes an InputError naming the file and line."""
    path = Path(path)
    try:
        with open(path, "rb") as fh:
            return tomllib.load(fh)
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"{path}: invalid TOML: {exc}") from None


def jsonable(obj):
    """Convert numpy scalars/arrays, paths and non-finite floats (→ null) for ``json.dumps``."""
    if isinstance(obj, dict):
        return {str(k): jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return jsonable(obj.tolist())
    if isinstance(obj, (np.bool_, bool)):
        return bool(obj)
    if isinstance(obj, (np.integer, int)):
        return int(obj)
    if isinstance(obj, (np.floating, float)):
        return float(obj) if math.isfinite(obj) else None
    if isinstance(obj, os.PathLike):
        return os.fspath(obj)
    return obj


def print_json(obj: dict) -> None:
    """Print one JSON object on stdout (the ``--json`` contract)."""
    sys.stdout.write(json.dumps(jsonable(obj), indent=2, allow_nan=False) + "\n")
