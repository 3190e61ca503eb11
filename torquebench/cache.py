"""Content-addressed on-disk cache of stage results (pickles with a SHA-256 header).

Entry ``<dir>/<key>.pkl`` = 64 hex chars of sha256(payload) + newline + payload, the payload the
pickle of ``(key, value)``. A truncated, corrupt or misplaced entry fails the check: one line on stderr, the entry is removed and the stage recomputed.
Directory: $TORQUEBENCH_CACHE or ./.torquebench-cache.

The cache knows its own entries: every entry it writes is appended to ``<dir>/.torquebench-cache.manifest``
(one key a line, appended with O_APPEND so concurrent sweep workers never lose a line). ``info``
counts, ``clear`` removes, and a corrupt-entry check deletes only files listed there: a user's
own ``*.pkl`` in the same directory is never touched. An entry path held by a file the cache did
not write is neither read nor replaced (the stage is recomputed and not cached).
"""

from __future__ import annotations

import hashlib
import os
import pickle
import re
import sys
from pathlib import Path

from userio.errors import InputError
from userio.files import write_bytes_atomic

MANIFEST = ".torquebench-cache.manifest"
_KEY = re.compile(r"[0-9a-f]{16,128}")


def default_dir() -> Path:
    return Path(os.environ.get("TORQUEBENCH_CACHE", ".torquebench-cache"))


class Cache:
    def __init__(self, directory: Path | None = None):
        self.dir = Path(directory) if directory is not None else default_dir()
        self._where = "--cache-dir" if directory is not None else (
            "$TORQUEBENCH_CACHE" if "TORQUEBENCH_CACHE" in os.environ else "cache directory")
        if self.dir.exists() and not self.dir.is_dir():
            raise InputError(f"{self._where}: {self.dir} exists and is not a directory")

    def _path(self, key: str) -> Path:
        return self.dir / f"{key}.pkl"

    def keys(self) -> list[str]:
        """The keys this cache wrote (its manifest), that are still present."""
        try:
            text = (self.dir / MANIFEST).read_text(encoding="utf-8", errors="replace")
        except OSError:
            return []
        keys = dict.fromkeys(k for k in text.split() if _KEY.fullmatch(k))
        return [k for k in keys if self._path(k).is_file()]

    def _own(self, key: str) -> bool:
        return key in self.keys()

    def has(self, key: str) -> bool:
        return self._path(key).is_file() and self._own(key)

    def get(self, key: str, expect: type | tuple | None = None):
        """The stored value, or None (missing, not this cache's, or corrupt: reported in one line
        and removed; ``expect``: the type the stage stores — anything else is corrupt too)."""
        p = self._path(key)
        if not self._own(key):
            return None
        try:
            data = p.read_bytes()
        except OSError:
            return None
        head, _, payload = data.partition(b"\n")
        value = None
        ok = hashlib.sha256(payload).hexdigest().encode() == head
        if ok:
            try:
                stored = pickle.loads(payload)
            except Exception:          # noqa: BLE001 — an entry of another version of the code
                stored = None
            # (key, value): an entry copied or renamed onto another key is not this key's result
            ok = isinstance(stored, tuple) and len(stored) == 2 and stored[0] == key
            value = stored[1] if ok else None
        if ok and expect is not None and not isinstance(value, expect):
            ok = False
        if not ok:
            print(f"cache: {p}: corrupt or truncated entry (or one of another version); recomputing", file=sys.stderr)
            try:
                p.unlink(missing_ok=True)
            except OSError:
                pass
            return None
        return value

    def put(self, key: str, value) -> None:
        if not _KEY.fullmatch(key):
            raise ValueError(f"cache key {key!r} is not a hex digest")
        try:
            self.dir.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise InputError(f"{self._where}: cannot create {self.dir}: {exc.strerror}") from None
        p = self._path(key)
        if os.path.lexists(p) and not self._own(key):
            return                      # a file the cache did not write: left alone, not cached
        payload = pickle.dumps((key, value), protocol=pickle.HIGHEST_PROTOCOL)
        write_bytes_atomic(p, hashlib.sha256(payload).hexdigest().encode() + b"\n" + payload,
                           policy=False)
        try:
            fd = os.open(self.dir / MANIFEST, os.O_WRONLY | os.O_APPEND | os.O_CREAT | os.O_NOFOLLOW, 0o644)
            with os.fdopen(fd, "a") as f:
                f.write(key + "\n")
        except OSError as exc:
            raise InputError(f"{self._where}: cannot record the entry in {self.dir / MANIFEST}: "
                             f"{exc.strerror}") from None

    def info(self) -> dict:
        keys = self.keys() if self.dir.is_dir() else []
        others = len([f for f in self.dir.glob("*.pkl") if f.stem not in set(keys)]) if self.dir.is_dir() else 0
        sizes = []
        for k in keys:               # an entry removed since it was listed (a concurrent clear or run) is not counted
            try:
                sizes.append(self._path(k).stat().st_size)
            except FileNotFoundError:
                pass
        return {"directory": str(self.dir), "entries": len(sizes), "size_bytes": int(sum(sizes)),
                "other_files": others}

    def clear(self) -> int:
        """Remove this cache's entries (its manifest's); other files in the directory stay."""
        if not self.dir.is_dir():
            return 0
        keys = self.keys()
        for k in keys:
            self._path(k).unlink(missing_ok=True)
        try:
            (self.dir / MANIFEST).unlink(missing_ok=True)
        except OSError:
            pass
        return len(keys)
