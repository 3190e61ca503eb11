"""Content-addressed on-disk cache of stage results (pickles with a SHA-256 header).

Entry ``<dir>/<key>.pkl`` = 64 hex chars of sha256(payload) + newline + payload. A truncated or
corrupt entry fails the check: one line on stderr, the entry is removed and the stage recomputed.
Writes go through userio.files.write_bytes_atomic. Directory: $TORQUEBENCH_CACHE or ./.torquebench-cache.
"""

from __future__ import annotations

import hashlib
import os
import pickle
import sys
from pathlib import Path

from userio.files import write_bytes_atomic


def default_dir() -> Path:
    return Path(os.environ.get("TORQUEBENCH_CACHE", ".torquebench-cache"))


class Cache:
    def __init__(self, directory: Path | None = None):
        self.dir = Path(directory) if directory is not None else default_dir()

    def _path(self, key: str) -> Path:
        return self.dir / f"{key}.pkl"

    def has(self, key: str) -> bool:
        return self._path(key).is_file()

    def get(self, key: str):
        """The stored value, or None (missing, or corrupt: reported in one line and removed)."""
        p = self._path(key)
        try:
            data = p.read_bytes()
        except OSError:
            return None
        head, _, payload = data.partition(b"\n")
        if hashlib.sha256(payload).hexdigest().encode() != head:
            print(f"cache: {p}: corrupt or truncated entry; recomputing", file=sys.stderr)
            p.unlink(missing_ok=True)
            return None
        return pickle.loads(payload)

    def put(self, key: str, value) -> None:
        self.dir.mkdir(parents=True, exist_ok=True)
        payload = pickle.dumps(value, protocol=pickle.HIGHEST_PROTOCOL)
        write_bytes_atomic(self._path(key), hashlib.sha256(payload).hexdigest().encode() + b"\n" + payload)

    def info(self) -> dict:
        files = list(self.dir.glob("*.pkl")) if self.dir.is_dir() else []
        return {"directory": str(self.dir), "entries": len(files),
                "size_bytes": int(sum(f.stat().st_size for f in files))}

    def clear(self) -> int:
        files = list(self.dir.glob("*.pkl")) if self.dir.is_dir() else []
        for f in files:
            f.unlink(missing_ok=True)
        return len(files)
