"""The commands' stdout and the repository's own files: ``--json`` prints exactly one JSON object
(numbers in SI units, NaN as null); ``shipped`` names a file shipped with the project. Files are
written through ``userio.files`` under the rules of ``userio.outputs``.
"""

from __future__ import annotations

import json
import math
import os
import sys
from pathlib import Path

import numpy as np

REPO_ROOT = Path(__file__).resolve().parents[1]


def shipped(kind: str, name: str) -> Path:
    """Path of a file shipped with the project, e.g. ``shipped("robots", "paper_leg.toml")``."""
    return REPO_ROOT / kind / name


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
