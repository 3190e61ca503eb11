"""One output policy for every command: what a run may write, known and checked before it starts,
and enforced again at every write.

A command declares what it reads and what it writes on an :class:`Outputs` plan, calls
:meth:`Outputs.check` before any work, and runs inside ``with plan.active():``. Every writer of the
project (``userio.files.atomic_path``, ``write_files_atomic``, ``remove``) asks the active plan when
it starts and again at the final rename, so a file that appears during a long run is not replaced.

Rules (a refusal is an InputError naming the option and the path; the CLI exits 2):

1. An output is never an input: not the same path after ``..`` and symlinks are resolved, not the
   same inode (hard links, bind mounts). The inputs of a log include its side files
   ``LOG.timing.toml`` and ``LOG.noise.toml`` (also when absent: a file written there would change
   what the log means), and a scene's robot, sensor, calibration, design and log files.
2. No two outputs are the same file.
3. Outputs stay where the user named them: a name built from data (a scene's name) goes through
   :func:`safe_stem`, and a file written into an output directory must lie inside it.
4. An existing file is replaced only with ``--force``, or when it is the tool's own: listed in the
   output directory's manifest (``.torquebench-outputs.json``) with the content the tool wrote.
   Otherwise the final step is an exclusive link, which fails if the target appeared meanwhile.
5. Directories, devices, FIFOs and sockets are never replaced, ``--force`` or not.
6. Missing directories are created; a file in the way, a read-only or full file system, or a
   directory that cannot be created is refused up front, naming the path and the cause.
7. Nothing is removed that the tool did not write (``remove`` obeys rules 1–5).
8. A report directory holding a file of a name a builder may write (``names``) that the tool did
   not write is refused up front (rule 4 for names known only while building).
9. Versioned outputs (``free_version``): instead of replacing, the first free ``NAME.vK.SUFFIX``
   whose companion files are free too.

This module is the only place of these rules: the writers (``userio.files``) ask it, the commands
declare their plans on it (``torquebench.outputs`` declares what a scene run reads and writes),
and ``tests/test_output_options.py`` runs every command's output options against it.
"""

from __future__ import annotations

import errno
import hashlib
import json
import os
import re
import stat
from contextlib import contextmanager
from pathlib import Path

from userio.errors import InputError

MANIFEST = ".torquebench-outputs.json"
MIN_FREE_BYTES = 1 << 20            # a file system with less room than this is "full" up front

_ACTIVE: list["Outputs"] = []       # a stack: the plan of the running command (threads see it too)
_REQUIRED: list[bool] = []          # inside a command (the CLI): every write needs an active plan


@contextmanager
def required():
    """Within the block (a CLI command) a write outside an active plan is a bug, not a user
    error: every command declares what it writes (``tests/test_output_options.py``)."""
    _REQUIRED.append(True)
    try:
        yield
    finally:
        _REQUIRED.pop()


def unplanned(path) -> None:
    """Called by the writers when no plan is active: refuse inside a command (``required``)."""
    if _REQUIRED:
        raise RuntimeError(f"{path}: written outside the command's output plan (a bug: every "
                           "command declares its outputs on userio.outputs.Outputs)")


def current() -> "Outputs | None":
    """The active plan, or None (library use: the writers' own ``overwrite`` flag decides)."""
    return _ACTIVE[-1] if _ACTIVE else None


# ----------------------------------------------------------------------------------- small rules
def safe_stem(name: str, default: str = "output") -> str:
    """A file stem from a free-text name: letters, digits, ``-``, ``_``, ``.`` kept, anything else
    (path separators, ``..``, spaces, control characters) replaced by ``_``; no leading dot;
    at most 100 characters. ``"../../escaped"`` → ``"escaped"``; ``""`` → ``default``."""
    s = re.sub(r"[^A-Za-z0-9._-]+", "_", str(name))
    s = re.sub(r"\.{2,}", "_", s).strip("._ ")[:100].strip("._ ")
    return s or default


def same_file(a: Path, b: Path) -> bool:
    """Same file: equal real paths, or (both existing) the same inode (hard links, bind mounts)."""
    if os.path.realpath(a) == os.path.realpath(b):
        return True
    try:
        return os.path.samefile(a, b)
    except (OSError, ValueError):
        return False


def kind_of(path: Path) -> str | None:
    """'file', 'symlink', 'directory', 'device', 'fifo', 'socket' or None (absent) — not following
    a symlink."""
    try:
        st = os.lstat(path)
    except FileNotFoundError:
        return None
    except NotADirectoryError:
        raise InputError(f"{path}: a parent of it is not a directory") from None
    except OSError as exc:
        raise InputError(f"{path}: cannot inspect it: {exc.strerror}") from None
    m = st.st_mode
    if stat.S_ISLNK(m):
        return "symlink"
    if stat.S_ISREG(m):
        return "file"
    if stat.S_ISDIR(m):
        return "directory"
    if stat.S_ISCHR(m) or stat.S_ISBLK(m):
        return "device"
    if stat.S_ISFIFO(m):
        return "fifo"
    return "socket"


def log_side_files(log_path) -> list[Path]:
    """``LOG.timing.toml`` and ``LOG.noise.toml`` beside ``LOG.csv`` (what a log's reader reads too)."""
    p = Path(log_path)
    return [p.with_name(p.stem + ".timing.toml"), p.with_name(p.stem + ".noise.toml")]


def sha256_of(path: Path) -> str | None:
    try:
        h = hashlib.sha256()
        with open(path, "rb") as f:
            for block in iter(lambda: f.read(1 << 20), b""):
                h.update(block)
        return h.hexdigest()
    except OSError:
        return None


def os_error(exc: OSError, path=None, doing: str = "write") -> InputError:
    """An OSError as one line naming the path and the cause (read-only, full, permission...)."""
    where = exc.filename if exc.filename else path
    cause = exc.strerror or str(exc)
    if exc.errno == errno.ENOSPC:
        cause += " (the file system is full)"
    elif exc.errno == errno.EROFS:
        cause += " (mounted read-only)"
    return InputError(f"{where}: cannot {doing}: {cause}")


def room_problem(directory: Path) -> str | None:
    """Why files cannot be created in ``directory`` (or, when it is missing, in its nearest
    existing parent): a read-only or full file system, no permission; None when they can."""
    directory = Path(directory)
    while not directory.exists() and directory != directory.parent:
        directory = directory.parent
    try:
        vfs = os.statvfs(directory)
    except OSError:
        return None
    if vfs.f_flag & os.ST_RDONLY:
        return f"{directory} is on a read-only file system"
    if vfs.f_bavail * vfs.f_frsize < MIN_FREE_BYTES:
        return f"the file system of {directory} is full ({vfs.f_bavail * vfs.f_frsize} bytes free)"
    if not os.access(directory, os.W_OK | os.X_OK):
        return f"{directory}: permission denied (cannot create files there)"
    return None


def check_room(directory: Path, label: str) -> None:
    """Refuse, before the work, a directory on a read-only or full file system."""
    why = room_problem(directory)
    if why is not None:
        hint = ("choose another place" if "read-only" in why else "free some space or write elsewhere"
                if "full" in why else "")
        raise InputError(f"{label}: {why}" + (f"; {hint}" if hint else ""))


def make_dir(directory: Path, label: str) -> None:
    """Create ``directory`` (and its parents); a file in the way or an OS error → InputError."""
    k = kind_of(directory)
    if k == "directory" or (k == "symlink" and directory.is_dir()):
        return
    if k is not None:
        raise InputError(f"{label}: {directory} exists and is not a directory")
    try:
        directory.mkdir(parents=True, exist_ok=True)
    except FileExistsError:
        raise InputError(f"{label}: cannot create directory {directory}: a file is in the way") from None
    except NotADirectoryError:
        raise InputError(f"{label}: cannot create directory {directory}: a parent is a file") from None
    except OSError as exc:
        raise InputError(f"{label}: cannot create directory {directory}: {exc.strerror}") from None


# ----------------------------------------------------------------------------------- manifests
def _read_manifest(directory: Path) -> dict:
    p = directory / MANIFEST
    try:
        data = json.loads(p.read_text(encoding="utf-8"))
        files = data.get("files", {})
        return {str(k): str(v) for k, v in files.items()} if isinstance(files, dict) else {}
    except (OSError, ValueError, AttributeError):
        return {}


def _write_manifest(directory: Path, files: dict) -> None:
    """The manifest itself (an internal file: the tool's own, replaced atomically)."""
    import tempfile

    text = json.dumps({"written_by": "torquebench", "files": dict(sorted(files.items()))}, indent=1)
    try:
        fd, tmp = tempfile.mkstemp(prefix=f"{MANIFEST}.", dir=directory)
        with os.fdopen(fd, "w", encoding="utf-8") as f:
            f.write(text + "\n")
        os.replace(tmp, directory / MANIFEST)
    except OSError:                   # the outputs are written; only the bookkeeping is lost
        try:
            os.unlink(tmp)
        except (OSError, UnboundLocalError):
            pass


def is_own(path: Path) -> bool:
    """``path`` is a file this tool wrote into its directory and nobody changed since."""
    path = Path(path)
    if kind_of(path) != "file":
        return False
    digest = _read_manifest(path.parent).get(path.name)
    return digest is not None and digest == sha256_of(path)


# ----------------------------------------------------------------------------------- the plan
class Outputs:
    """The inputs and outputs of one run (see the module doc for the rules)."""

    def __init__(self, *, force: bool = False, force_flag: str | None = "--force"):
        self.force, self.force_flag = bool(force), force_flag
        self.inputs: list[tuple[str, Path]] = []
        self.files: list[tuple[str, Path]] = []
        self.dirs: list[tuple[str, Path, bool]] = []      # (label, dir, shipped: every file is the tool's)
        self.names: list[tuple[str, Path, tuple]] = []    # (label, dir, name parts a builder may write)
        self.checked = False

    # ---------------------------------------------------------------- declaring
    def input(self, label: str, path, *, log: bool = False) -> Path | None:
        """Declare a file read (``log``: also its side files); None is skipped."""
        if path is None:
            return None
        path = Path(path)
        self.inputs.append((label, path))
        if log:
            for side in log_side_files(path):
                self.inputs.append((f"{label}'s side file", side))
        return path

    def file(self, label: str, path) -> Path | None:
        """Declare an output file (a name the user gave); None is skipped."""
        if path is None:
            return None
        path = Path(path)
        self.files.append((label, path))
        return path

    def directory(self, label: str, path, *, shipped: bool = False, names=()) -> Path:
        """Declare an output directory (files are written inside it; ``shipped``: the repository's
        own reports, every file in it the tool's to regenerate; ``names``: parts of the file names
        its builders may write, refused up front when such a file is not the tool's, rule 8)."""
        path = Path(path)
        self.dirs.append((label, path, shipped))
        if names and not shipped:
            self.names.append((label, path, tuple(names)))
        return path

    def file_in(self, label: str, directory, name: str) -> Path:
        """Declare the output ``directory/safe_stem(name)…`` (``name`` may carry a suffix)."""
        stem, dot, suffix = str(name).rpartition(".")
        if not dot or not re.fullmatch(r"[A-Za-z0-9]{1,10}", suffix):
            stem, suffix = str(name), ""
        path = Path(directory) / (safe_stem(stem) + (f".{suffix}" if suffix else ""))
        return self.file(label, path)

    # ---------------------------------------------------------------- checking
    def _replace_hint(self) -> str:
        return (f"add {self.force_flag} to replace it" if self.force_flag
                else "remove it or choose another name")

    def _refuse_existing(self, label: str, path: Path, during: bool = False) -> InputError:
        when = " (it appeared during the run and was kept)" if during else ""
        return InputError(f"{label}: {path} exists{when}; {self._replace_hint()}")

    def _label_of(self, path: Path) -> str:
        for label, p in self.files:
            if same_file(p, path):
                return label
        for label, d, _ in self.dirs:
            if _inside(path, d):
                return label
        return str(path)

    def _check_target(self, label: str, path: Path, *, exclusive_ok: bool = True) -> str:
        """'new' | 'replace' for one output path, or an InputError (rules 1, 4, 5)."""
        for ilabel, p in self.inputs:
            if same_file(path, p):
                what = "" if ilabel == label else f" {ilabel}"
                raise InputError(f"{label}: {path} is the input{what}; refusing to overwrite an input")
        k = kind_of(path)
        if k is None:
            return "new"
        if k == "directory" or (k == "symlink" and path.is_dir()):
            raise InputError(f"{label}: {path} is a directory; give a file name")
        if k in ("device", "fifo", "socket"):
            raise InputError(f"{label}: {path} is a {k}, not a regular file; refusing to write to it")
        if k == "symlink":
            target = Path(os.path.realpath(path))
            if kind_of(target) in ("device", "fifo", "socket"):
                raise InputError(f"{label}: {path} links to a {kind_of(target)}; refusing to write to it")
        if self.force or self._own(path):
            return "replace"
        raise self._refuse_existing(label, path)

    def _own(self, path: Path) -> bool:
        for _, d, shipped in self.dirs:
            if _inside(path, d) and (shipped or is_own(path)):
                return kind_of(path) == "file"
        return False

    def check(self) -> "Outputs":
        """Every rule that can be checked before the work; creates the missing directories."""
        for label, d, _ in self.dirs:
            for ilabel, p in self.inputs:
                if same_file(d, p):
                    raise InputError(f"{label}: {d} is the input {ilabel}")
            k = kind_of(d)
            if k is not None and not d.is_dir():
                raise InputError(f"{label}: {d} exists and is not a directory")
        for i, (label, path) in enumerate(self.files):
            for label2, other in self.files[:i]:
                if same_file(path, other):
                    raise InputError(f"{label}: {path} is also written as {label2}; two outputs would "
                                     "overwrite each other")
            self._check_target(label, path)
            if kind_of(path.parent) not in (None, "directory", "symlink") or \
                    (path.parent.exists() and not path.parent.is_dir()):
                raise InputError(f"{label}: {path.parent} exists and is not a directory")
        for label, path in self.files:
            make_dir(path.parent, label)
            check_room(path.parent, label)
        for label, d, _ in self.dirs:
            make_dir(d, label)
            check_room(d, label)
        for label, d, names in self.names:
            clash = foreign_files(d, names, self.force)
            if clash:
                raise InputError(f"{label}: {clash[0]} exists and was not written by torquebench "
                                 f"({len(clash)} such file(s) with a name the run writes); "
                                 + (f"add {self.force_flag} to replace it or " if self.force_flag else "")
                                 + "choose another directory")
        self.checked = True
        return self

    @contextmanager
    def active(self):
        """Run the block with this plan enforced by every writer."""
        if not self.checked:
            self.check()
        _ACTIVE.append(self)
        try:
            yield self
        finally:
            _ACTIVE.remove(self)

    # ---------------------------------------------------------------- used by the writers
    def admit(self, path, *, final: bool = False) -> str:
        """How ``path`` may be written now: 'new' (exclusive create) or 'replace'; refuses a path
        that is not a declared output (or inside a declared directory), or that breaks a rule."""
        path = Path(path)
        label = self._label_of(path)
        declared = any(same_file(p, path) for _, p in self.files) or \
            any(_inside(path, d) for _, d, _ in self.dirs)
        if not declared:
            raise InputError(f"{path}: not an output this command declared; refusing to write it "
                             "(a bug: please report it)")
        try:
            return self._check_target(label, path)
        except InputError:
            if final and kind_of(path) == "file" and not self.force:
                raise self._refuse_existing(label, path, during=True) from None
            raise

    def wrote(self, path) -> None:
        """Record a written file in its directory's manifest (directory outputs only)."""
        path = Path(path)
        for _, d, shipped in self.dirs:
            if _inside(path, d) and not shipped:
                files = _read_manifest(path.parent)
                files[path.name] = sha256_of(path) or ""
                _write_manifest(path.parent, files)
                return


def _inside(path: Path, directory: Path) -> bool:
    """``path`` lies strictly inside ``directory`` (``..`` and symlinks of the directory resolved)."""
    try:
        p = Path(os.path.realpath(Path(path).parent)) / Path(path).name
        d = Path(os.path.realpath(directory))
    except (OSError, ValueError):
        return False
    return d in p.parents


# ----------------------------------------------------------------------------------- placing
def place(tmp, path, mode: str) -> None:
    """Move the finished temp file onto ``path``: 'replace' (atomic rename) or 'new' (hard link,
    which fails if ``path`` appeared meanwhile, then the temp is unlinked)."""
    if mode == "replace":
        os.replace(tmp, path)
        return
    try:
        os.link(tmp, path)
    except FileExistsError:
        plan = current()
        if plan is not None:
            raise plan._refuse_existing(plan._label_of(Path(path)), Path(path), during=True) from None
        raise InputError(f"{path}: exists; refusing to overwrite it") from None
    except OSError as exc:
        if exc.errno not in (errno.EPERM, errno.EMLINK, errno.EOPNOTSUPP, errno.ENOSYS):
            raise
        # a file system without hard links: create the target exclusively, then rename over it
        fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
        os.close(fd)
        os.replace(tmp, path)
        return
    os.unlink(tmp)


# ----------------------------------------------------------------------------------- more rules
def foreign_files(out_dir, names, force: bool = False) -> list[Path]:
    """Files in ``out_dir`` that a builder may write (a name containing one of ``names``;
    .md/.png/.csv/.json) and that the tool did not write there (its manifest), rule 8."""
    out_dir = Path(out_dir)
    if force or not out_dir.is_dir():
        return []
    return sorted(p for p in out_dir.iterdir() if p.suffix in (".md", ".png", ".csv", ".json")
                  and any(n.lower() in p.name.lower() for n in names) and not is_own(p))


def distinct(outputs) -> None:
    """Rule 2 for a set written together: ``[(label, path)]`` naming no file twice."""
    outputs = [(str(label), Path(p)) for label, p in outputs]
    for i, (label, path) in enumerate(outputs):
        for label2, other in outputs[:i]:
            if same_file(path, other):
                raise InputError(f"{label}: {path} is also written as {label2}; two outputs would "
                                 "overwrite each other")


def free_version(path, companions=lambda p: ()) -> Path:
    """Rule 9: ``path`` if it and its ``companions(path)`` are free, else the first
    ``NAME.vK.SUFFIX`` (K = 2, 3, ...) free with its companions (nothing is replaced)."""
    path = Path(path)

    def free(c: Path) -> bool:
        return not os.path.lexists(c) and not any(os.path.lexists(p) for p in companions(c))

    if free(path):
        return path
    k = 2
    while not free(cand := path.with_name(f"{path.stem}.v{k}{path.suffix}")):
        k += 1
    return cand


def default_dir(out_dir, *, default: str, shipped_dir=None, regenerate: bool = False,
                option: str = "--out-dir") -> Path:
    """Where a report command writes: ``out_dir`` if given; the shipped reports directory only when
    ``regenerate`` is asked explicitly; else ``./<default>``. Shipped reports are never the
    default's target. The directory is declared and created by the plan (``Outputs.directory``)."""
    if out_dir is not None and regenerate:
        raise InputError(f"{option}: give either {option} or --regenerate-shipped, not both")
    if regenerate:
        return Path(shipped_dir)
    if out_dir is not None:
        return Path(out_dir)
    path = Path.cwd() / default
    if shipped_dir is not None and same_file(path, Path(shipped_dir)):
        raise InputError(f"{option}: {path} is the shipped reports directory; pass "
                         "--regenerate-shipped to replace the shipped reports")
    return path
