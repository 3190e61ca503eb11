"""Atomic file writes for the calibration package (temp file + fsync + rename).

The domain packages must not import ``torquebench``, so this mirrors ``torquebench.io``:
a file appears whole or not at all, and with ``overwrite=False`` an existing file is never
replaced (``os.link`` of the finished temp file fails atomically if the target exists).
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

from calibration.errors import InputError


def _umask() -> int:
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def _fsync_dir(directory: Path) -> None:
    try:
        fd = os.open(directory, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def write_bytes_atomic(path: str | os.PathLike, data: bytes, *, overwrite: bool = True) -> Path:
    """Write ``data`` to ``path`` atomically; ``overwrite=False`` raises InputError if it exists."""
    path = Path(path)
    if not path.parent.exists():
        raise InputError(f"{path}: directory {path.parent} does not exist")
    if not overwrite and path.exists():
        raise InputError(f"{path}: exists; refusing to overwrite it")
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        os.fchmod(fd, 0o666 & ~_umask())          # mkstemp makes 0600; use the usual mode
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())
        if overwrite:
            os.replace(tmp, path)
        else:
            try:
                os.link(tmp, path)            # atomic "create if absent"
            except FileExistsError:
                raise InputError(f"{path}: exists; refusing to overwrite it") from None
            os.unlink(tmp)
        _fsync_dir(path.parent)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path


def write_text_atomic(path: str | os.PathLike, text: str, *, overwrite: bool = True) -> Path:
    """Text version of :func:`write_bytes_atomic` (UTF-8)."""
    return write_bytes_atomic(path, text.encode("utf-8"), overwrite=overwrite)


def next_version_path(path: str | os.PathLike) -> Path:
    """First free ``NAME.vK.SUFFIX`` (K = 2, 3, ...) beside ``path``."""
    path = Path(path)
    k = 2
    while True:
        cand = path.with_name(f"{path.stem}.v{k}{path.suffix}")
        if not cand.exists():
            return cand
        k += 1
