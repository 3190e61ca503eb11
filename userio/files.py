"""Files the tool writes appear whole or not at all (temp file beside the target + rename).

Contract (CONTRIBUTING.md): nothing a user gave is overwritten or lost on an error. With
``overwrite=False`` an existing file is never replaced: the finished temp file is hard-linked
onto the target, which fails atomically if the target exists.
"""

from __future__ import annotations

import errno
import os
import stat
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


def _mode(path: Path, overwrite: bool, policy: bool, final: bool = False) -> str:
    """'new' (exclusive create) or 'replace' for ``path``: the active output plan decides
    (userio.outputs), else ``overwrite``."""
    from userio import outputs

    plan = outputs.current() if policy else None
    if plan is not None:
        return plan.admit(path, final=final)
    if policy:
        outputs.unplanned(path)
    if not overwrite and os.path.lexists(path):
        raise _refuse_existing(path)
    return "replace" if overwrite else "new"


def _mkstemp_beside(path: Path) -> str:
    """A temp file beside ``path`` (same suffix) with the usual file mode; OS errors named."""
    from userio.outputs import os_error

    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name[:80]}.", suffix=path.suffix[:16], dir=path.parent)
    except OSError as exc:
        raise os_error(exc, path) from None
    os.fchmod(fd, 0o666 & ~_umask())          # mkstemp makes 0600; written files get the usual mode
    os.close(fd)
    return tmp


@contextmanager
def atomic_path(path: str | os.PathLike, *, overwrite: bool = True, policy: bool = True):
    """Yield a temporary path beside ``path`` (same suffix); move it onto ``path`` only if the
    block succeeds. On any exception, Ctrl-C included, the temp file is removed and ``path`` is
    untouched. With ``overwrite=False`` an existing ``path`` is an InputError. Under an active
    output plan (userio.outputs) the plan decides instead, at the start and again at the final
    rename (a file that appeared meanwhile is kept); ``policy=False``: the caller's own rules."""
    from userio.outputs import os_error, place

    path = Path(path)
    mode = _mode(path, overwrite, policy)
    if not path.parent.is_dir():
        raise InputError(f"{path}: directory {path.parent} does not exist")
    tmp = _mkstemp_beside(path)
    try:
        try:
            yield Path(tmp)
        except OSError as exc:
            if exc.errno in _STORAGE_ERRNOS:
                raise os_error(exc, path) from None
            raise
        mode = _mode(path, overwrite, policy, final=True)
        try:
            place(tmp, path, mode)
        except OSError as exc:
            raise os_error(exc, path) from None
        _fsync_dir(path.parent)
        _record(path, policy)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


_STORAGE_ERRNOS = {errno.ENOSPC, errno.EROFS, errno.EDQUOT, errno.EIO, errno.EFBIG, errno.EACCES,
                   errno.EPERM}


def _record(path: Path, policy: bool) -> None:
    from userio import outputs

    plan = outputs.current() if policy else None
    if plan is not None:
        plan.wrote(path)


def remove(path: str | os.PathLike) -> bool:
    """Remove an output file of this run (a stale one of a set): allowed only where the active plan
    would let the file be replaced (declared, not an input, --force or the tool's own). Returns
    whether a file was removed."""
    from userio import outputs

    path = Path(path)
    if not os.path.lexists(path):
        return False
    plan = outputs.current()
    if plan is None:
        outputs.unplanned(path)
    if plan is None or plan.admit(path) != "replace":
        raise InputError(f"{path}: refusing to remove a file this command did not write")
    path.unlink()
    return True


def atomic_write(path: str | os.PathLike, write_fn, *, overwrite: bool = True) -> Path:
    """Call ``write_fn(tmp)`` (tmp: a str path with ``path``'s suffix), then move it onto ``path``."""
    with atomic_path(path, overwrite=overwrite) as tmp:
        write_fn(str(tmp))
    return Path(path)


def write_bytes_atomic(path: str | os.PathLike, data: bytes, *, overwrite: bool = True,
                       policy: bool = True) -> Path:
    """Write ``data`` to ``path`` atomically (temp file + fsync + rename)."""
    with atomic_path(path, overwrite=overwrite, policy=policy) as tmp:
        with open(tmp, "wb") as fh:
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())
    return Path(path)


def write_text_atomic(path: str | os.PathLike, text: str, *, overwrite: bool = True) -> Path:
    """Text (UTF-8) version of :func:`write_bytes_atomic`."""
    return write_bytes_atomic(path, text.encode("utf-8"), overwrite=overwrite)


MAX_TEXT_INPUT_BYTES = 64 << 20       # a TOML, JSON or small CSV file the tool reads whole


def check_input(path: str | os.PathLike, label: str | None = None, *,
                max_bytes: int | None = MAX_TEXT_INPUT_BYTES, what: str = "file") -> Path:
    """An input file, checked before it is read: it exists, is a regular file (not a directory, a
    device such as /dev/zero, a FIFO or a socket) and is at most ``max_bytes`` long. Every refusal
    is one InputError naming the path and what it is."""
    path = Path(path)
    where = f"{label}: {path}" if label else f"{path}"
    try:
        st = os.stat(path)
    except FileNotFoundError:
        broken = " (a symlink whose target is missing)" if os.path.islink(path) else ""
        raise InputError(f"{where}: {what} not found{broken}") from None
    except NotADirectoryError:
        raise InputError(f"{where}: {what} not found (a parent is a file)") from None
    except OSError as exc:
        raise InputError(f"{where}: cannot read it: {exc.strerror}") from None
    m = st.st_mode
    if stat.S_ISDIR(m):
        raise InputError(f"{where}: is a directory, expected a {what}")
    if not stat.S_ISREG(m):
        kind = ("a device" if stat.S_ISCHR(m) or stat.S_ISBLK(m) else "a FIFO (named pipe)"
                if stat.S_ISFIFO(m) else "a socket")
        raise InputError(f"{where}: is {kind}, not a regular file; expected a {what}")
    if max_bytes is not None and st.st_size > max_bytes:
        raise InputError(f"{where}: {st.st_size / 2**20:.1f} MiB, above the {max_bytes / 2**20:.0f} MiB "
                         f"a {what} of this kind may hold; is it the right file?")
    if not os.access(path, os.R_OK):
        raise InputError(f"{where}: permission denied")
    return path


def read_toml(path: str | os.PathLike) -> dict:
    """Parse a TOML file; a syntax or encoding error becomes an InputError naming the file."""
    path = check_input(path, what="TOML file")
    try:
        with open(path, "rb") as fh:
            return tomllib.load(fh)
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"{path}: invalid TOML: {exc}") from None
    except UnicodeDecodeError as exc:
        raise InputError(f"{path}: not UTF-8 text (byte {exc.start}); TOML files must be UTF-8") from None
    except RecursionError:
        raise InputError(f"{path}: invalid TOML: nested too deeply") from None


def write_files_atomic(files, *, overwrite: bool = True) -> list[Path]:
    """Write several files as a set: all of them or none.

    ``files``: ``[(path, write_fn)]``, ``write_fn(tmp_path_str)`` writes one file (or
    ``(path, bytes|str)``). Every file is first written to a temp name beside its target; only
    when all succeeded are they moved onto the targets. Files that existed are first kept
    as hidden backups and put back if a move fails; on any error (Ctrl-C included) the temps
    are removed and the old files are left as they were. ``overwrite=False``: an existing
    target is an InputError before anything is written. Under an active output plan
    (userio.outputs) the plan decides per file, before and again at the final move.
    """
    from userio.outputs import distinct, os_error, place

    items = []
    for path, what in files:
        path = Path(path)
        if callable(what):
            fn = what
        else:
            data = what.encode("utf-8") if isinstance(what, str) else bytes(what)
            fn = (lambda d: (lambda tmp: Path(tmp).write_bytes(d)))(data)
        items.append((path, fn))
    distinct([(str(p), p) for p, _ in items])
    for p, _ in items:
        if p.is_dir():
            raise InputError(f"{p}: is a directory, not a file")
        if not p.parent.is_dir():
            raise InputError(f"{p}: directory {p.parent} does not exist")
    for p, _ in items:
        _mode(p, overwrite, True)
    temps: list[Path] = []
    backups: list[tuple[Path, Path]] = []
    done: list[Path] = []
    try:
        try:
            for p, fn in items:
                tmp = _mkstemp_beside(p)
                temps.append(Path(tmp))
                fn(tmp)
                with open(tmp, "rb+") as fh:
                    os.fsync(fh.fileno())
            modes = [_mode(p, overwrite, True, final=True) for p, _ in items]
            for (p, _), mode in zip(items, modes):      # keep the old files until all are in place
                if mode == "replace" and os.path.lexists(p):
                    fd, bak = tempfile.mkstemp(prefix=f".{p.name[:80]}.", suffix=".bak", dir=p.parent)
                    os.close(fd)
                    os.unlink(bak)
                    os.link(p, bak, follow_symlinks=False)
                    backups.append((p, Path(bak)))
            for (p, _), tmp, mode in zip(items, temps, modes):
                place(tmp, p, mode)
                done.append(p)
        except OSError as exc:
            if exc.errno in _STORAGE_ERRNOS:
                raise os_error(exc) from None
            raise
        for p in {p.parent for p, _ in items}:
            _fsync_dir(p)
    except BaseException:
        for t in temps:
            t.unlink(missing_ok=True)
        restored = {p for p, _ in backups}
        for p, bak in backups:
            if p in done:
                os.replace(bak, p)
        for p in done:
            if p not in restored:
                p.unlink(missing_ok=True)
        for _, bak in backups:
            bak.unlink(missing_ok=True)
        raise
    for _, bak in backups:
        bak.unlink(missing_ok=True)
    for p, _ in items:
        _record(p, True)
    return [p for p, _ in items]
