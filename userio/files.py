"""Files the tool writes appear whole or not at all (temp file beside the target + rename).

Contract (DESIGN.md): nothing a user gave is overwritten or lost on an error. With
``overwrite=False`` an existing file is never replaced: the finished temp file is hard-linked
onto the target, which fails atomically if the target exists.
"""

from __future__ import annotations

import os
import tempfile
import tomllib
from contextlib import contextmanager
from pathlib import Path

from userio.errors import InputError


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


def _refuse_existing(path: Path) -> InputError:
    return InputError(f"{path}: exists; refusing to overwrite it")


@contextmanager
def atomic_path(path: str | os.PathLike, *, overwrite: bool = True):
    """Yield a temporary path beside ``path`` (same suffix); move it onto ``path`` only if the
    block succeeds. On any exception, Ctrl-C included, the temp file is removed and ``path`` is
    untouched. With ``overwrite=False`` an existing ``path`` is an InputError."""
    path = Path(path)
    if not overwrite and path.exists():
        raise _refuse_existing(path)
    if not path.parent.is_dir():
        raise InputError(f"{path}: directory {path.parent} does not exist")
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=path.suffix, dir=path.parent)
    os.fchmod(fd, 0o666 & ~_umask())          # mkstemp makes 0600; written files get the usual mode
    os.close(fd)
    try:
        yield Path(tmp)
        if overwrite:
            os.replace(tmp, path)
        else:
            try:
                os.link(tmp, path)            # atomic "create if absent"
            except FileExistsError:
                raise _refuse_existing(path) from None
            os.unlink(tmp)
        _fsync_dir(path.parent)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def atomic_write(path: str | os.PathLike, write_fn, *, overwrite: bool = True) -> Path:
    """Call ``write_fn(tmp)`` (tmp: a str path with ``path``'s suffix), then move it onto ``path``."""
    with atomic_path(path, overwrite=overwrite) as tmp:
        write_fn(str(tmp))
    return Path(path)


def write_bytes_atomic(path: str | os.PathLike, data: bytes, *, overwrite: bool = True) -> Path:
    """Write ``data`` to ``path`` atomically (temp file + fsync + rename)."""
    with atomic_path(path, overwrite=overwrite) as tmp:
        with open(tmp, "wb") as fh:
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())
    return Path(path)


def write_text_atomic(path: str | os.PathLike, text: str, *, overwrite: bool = True) -> Path:
    """Text (UTF-8) version of :func:`write_bytes_atomic`."""
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


def read_toml(path: str | os.PathLike) -> dict:
    """Parse a TOML file; a syntax or encoding error becomes an InputError naming the file."""
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: file not found")
    try:
        with open(path, "rb") as fh:
            return tomllib.load(fh)
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"{path}: invalid TOML: {exc}") from None
    except UnicodeDecodeError as exc:
        raise InputError(f"{path}: not UTF-8 text (byte {exc.start}); TOML files must be UTF-8") from None
