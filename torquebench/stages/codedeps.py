"""The code a stage depends on, derived from the import graph (``ast``), not a hand list.

A stage's code is the source files of the modules that define its declaration's functions, and
every project file they import — at module level or inside a function, transitively, with the
``__init__`` of every package on the way (importing ``a.b.c`` runs ``a`` and ``a.b``). A project
file is a ``.py`` under SOURCE_ROOT in a package directory (one holding ``__init__.py``). An edit
to any of them changes the stage's key; an edit elsewhere does not. Not seen: imports by a
computed name (``importlib.import_module(x)``) and code reached only through the objects a stage
receives (that code belongs to the stage that made the object, whose key is upstream).
"""

from __future__ import annotations

import ast
import functools
import hashlib
import inspect
import re
import textwrap
from pathlib import Path

# an import statement's text: ``import a.b`` or ``from x import y`` / ``from x import (y,\n z)``
IMPORT_TEXT = re.compile(r"^[ \t]*(?:from[ \t]+[\w.]+[ \t]+import[ \t]*(?:\([^)]*\)|[^\n]*)|import[ \t]+[^\n]*)",
                         re.MULTILINE)

REPO_ROOT = Path(__file__).resolve().parents[2]      # where this checkout's packages sit
SOURCE_ROOT = REPO_ROOT                              # where the hashed source is read (tests move it)


def clear() -> None:
    """Forget the hashes and imports read so far (after an edit of the source, in tests)."""
    file_hash.cache_clear()
    file_imports.cache_clear()
    closure.cache_clear()


@functools.lru_cache(maxsize=None)
def file_hash(rel: str, root: Path | None = None) -> str:
    """SHA-256 of one source file (its relative path and bytes); "missing" for no such file."""
    p = (root or SOURCE_ROOT) / rel
    try:
        data = p.read_bytes()
    except OSError:
        return "missing"
    return hashlib.sha256(rel.encode() + b"\0" + data).hexdigest()[:16]


def _module_file(dotted: str, root: Path) -> str | None:
    """The project file of a dotted module name, or None (not a project module)."""
    parts = dotted.split(".")
    if not (root / parts[0] / "__init__.py").is_file():
        return None
    base = root.joinpath(*parts)
    if (base / "__init__.py").is_file():
        return (Path(*parts) / "__init__.py").as_posix()
    if base.with_suffix(".py").is_file():
        return Path(*parts).with_suffix(".py").as_posix()
    return None


def _with_parents(dotted: str, root: Path) -> set[str]:
    """The files importing ``dotted`` runs: every package ``__init__`` on its path and itself."""
    parts = dotted.split(".")
    out = set()
    for i in range(1, len(parts) + 1):
        f = _module_file(".".join(parts[:i]), root)
        if f is not None:
            out.add(f)
    return out


def _package_of(rel: str) -> list[str]:
    """The dotted package a file belongs to (for relative imports)."""
    parts = list(Path(rel).with_suffix("").parts)
    return parts[:-1]                                 # a package __init__ or a module: its folder


def _import_statements(body):
    """The import statements of a statement list and of every block nested in it (function and
    class bodies, if/try/with/loop blocks); expressions hold no imports and are not walked."""
    todo = list(body)
    while todo:
        node = todo.pop()
        if isinstance(node, (ast.Import, ast.ImportFrom)):
            yield node
            continue
        for field in ("body", "orelse", "finalbody", "handlers", "cases"):
            block = getattr(node, field, None)
            if isinstance(block, list):
                todo.extend(block)


def _import_nodes(text: str, rel: str) -> list:
    """The import statements of a source file. Fast path: only the text of its import statements
    is parsed (IMPORT_TEXT, each with ``ast``); one that does not parse alone (a ``;`` or a
    backslash continuation) → the whole file is parsed. A match inside a string adds a file, never
    loses one: the key may change more often than needed, never less."""
    nodes = []
    for m in IMPORT_TEXT.finditer(text):
        try:
            nodes += ast.parse(textwrap.dedent(m.group(0))).body
        except SyntaxError:
            try:
                return list(_import_statements(ast.parse(text, rel).body))
            except SyntaxError:
                return []
    return [n for n in nodes if isinstance(n, (ast.Import, ast.ImportFrom))]


@functools.lru_cache(maxsize=None)
def file_imports(rel: str, root: Path | None = None) -> frozenset[str]:
    """The project files one source file imports (module and function level), with the package
    ``__init__`` files on the way and those of its own package."""
    root = root or SOURCE_ROOT
    try:
        text = (root / rel).read_text()
    except (OSError, UnicodeDecodeError):
        return frozenset()
    out = _with_parents(".".join(_package_of(rel)), root) if _package_of(rel) else set()
    for node in _import_nodes(text, rel):
        if isinstance(node, ast.Import):
            for a in node.names:
                out |= _with_parents(a.name, root)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                pkg = _package_of(rel)
                pkg = pkg[:len(pkg) - (node.level - 1)]
                base = ".".join(pkg + ([base] if base else []))
            out |= _with_parents(base, root)
            for a in node.names:                      # ``from pkg import submodule``
                if _module_file(f"{base}.{a.name}", root):
                    out.add(_module_file(f"{base}.{a.name}", root))
    out.discard(rel)
    return frozenset(out)


@functools.lru_cache(maxsize=None)
def closure(start: frozenset[str], root: Path | None = None) -> tuple[str, ...]:
    """Every project file reachable from ``start`` through imports, sorted."""
    seen, todo = set(), list(start)
    while todo:
        f = todo.pop()
        if f not in seen:
            seen.add(f)
            todo.extend(file_imports(f, root or SOURCE_ROOT))
    return tuple(sorted(seen))


def source_file(fn) -> str | None:
    """The repository-relative file defining ``fn`` (None: not in this checkout)."""
    try:
        p = Path(inspect.getsourcefile(inspect.unwrap(fn))).resolve()
        return p.relative_to(REPO_ROOT).as_posix()
    except (TypeError, ValueError, OSError):
        return None


def stage_files(stage) -> tuple[str, ...]:
    """The source files a stage's declaration depends on (derived; see the module docstring)."""
    start = frozenset(f for f in map(source_file, stage.functions()) if f is not None)
    return closure(start, SOURCE_ROOT)


def stage_code(stage) -> dict[str, str]:
    """{file: hash} of every source file ``stage`` depends on."""
    return {f: file_hash(f, SOURCE_ROOT) for f in stage_files(stage)}


def code_version(stage) -> str:
    """One hash of the stage's code: part of its cache key."""
    blob = "\n".join(f"{f} {h}" for f, h in stage_code(stage).items())
    return hashlib.sha256(blob.encode()).hexdigest()[:16]
