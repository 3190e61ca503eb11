"""The same ``--out`` / ``--out-dir`` rules in every command.

- A missing output directory is created (with its parents).
- An existing output file the user stored is never replaced without ``--force``.
- An output path that is one of the command's inputs is refused outright.
Checked before any long computation, so a bad path fails in a second, not after the solve.
"""

from __future__ import annotations

from pathlib import Path

from torquebench.errors import InputError
from userio.files import same_file


def _mkdir(directory: Path, option: str) -> None:
    if directory.exists() and not directory.is_dir():
        raise InputError(f"{option}: {directory} exists and is not a directory")
    try:
        directory.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(f"{option}: cannot create directory {directory}: {exc.strerror}") from None


def prepare_dir(directory: str | Path, option: str) -> Path:
    """Create ``directory`` if missing; an existing file of that name is an InputError."""
    directory = Path(directory)
    _mkdir(directory, option)
    return directory


def prepare_file(path: str | Path | None, option: str, *, force: bool = False,
                 inputs: tuple = (), force_flag: str | None = "--force") -> Path | None:
    """Check an output file before the work: not an input, not an existing file unless ``force``;
    create its directory. Returns the path (None passes through). ``force_flag`` names the
    command's replace option in the message (None: the command has none, e.g. `propagate`,
    whose ``--force`` is the contact force)."""
    if path is None:
        return None
    path = Path(path)
    for given in inputs:
        if given is not None and same_file(path, Path(given)):
            raise InputError(f"{option}: {path} is an input of this command; refusing to overwrite an input")
    if path.is_dir():
        raise InputError(f"{option}: {path} is a directory; give a file name")
    if path.exists() and not force:
        how = f"add {force_flag} to replace it" if force_flag else "remove it or choose another name"
        raise InputError(f"{option}: {path} exists; {how}")
    _mkdir(path.parent, option)
    return path
