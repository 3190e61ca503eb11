"""Files the flexure package writes appear whole or not at all (temp file + rename)."""

from __future__ import annotations

import os
import tempfile
from pathlib import Path


def _umask() -> int:
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def atomic_write(path, write_fn) -> Path:
    """Call ``write_fn(tmp_path)`` on a temp file next to ``path``, then ``os.replace`` it into place.

    On any exception the temp file is removed and the exception re-raised (``path`` is untouched).
    The file gets mode 0o666 & ~umask, like a plain ``open(path, "w")``.
    """
    path = Path(path)
    fd, tmp = tempfile.mkstemp(suffix=path.suffix.lower(), prefix="." + path.name, dir=path.parent)
    os.close(fd)
    try:
        write_fn(tmp)
        os.chmod(tmp, 0o666 & ~_umask())
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except FileNotFoundError:
            pass
        raise
    return path
