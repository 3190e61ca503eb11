"""Every stage, found where it is declared: each module of the torquebench.stages package that
defines ``STAGES`` (a tuple of torquebench.stages.declaration.Stage) contributes them, and
``register`` adds one at run time (a plugin, a test). Nothing else lists the stages: adding one is
writing its declaration."""

from __future__ import annotations

import functools
import importlib
import pkgutil

_EXTRA: dict = {}


@functools.lru_cache(maxsize=None)
def _discovered() -> tuple:
    import torquebench.stages as pkg

    found = []
    for m in sorted(pkgutil.iter_modules(pkg.__path__), key=lambda m: m.name):
        found.extend(getattr(importlib.import_module(f"{pkg.__name__}.{m.name}"), "STAGES", ()))
    return tuple(found)


def register(stage):
    """Add ``stage`` to the graph (for this process); returns it."""
    if stage.name in {s.name for s in _discovered()}:
        raise ValueError(f"stage {stage.name!r} is already declared")
    _EXTRA[stage.name] = stage
    return stage


def unregister(name: str) -> None:
    _EXTRA.pop(name, None)


def stages() -> tuple:
    """Every stage in an execution order: each after the stages producing what it needs (depth
    first, in the order declared), the stages whose inputs are chosen from the rest of the plan
    (``Stage.inputs``: the report) after all others."""
    decl = [*_discovered(), *_EXTRA.values()]
    producer = {}
    for s in decl:
        if s.gives in producer:
            raise ValueError(f"stages {producer[s.gives].name!r} and {s.name!r} both produce {s.gives!r}")
        producer[s.gives] = s
    order, done = [], set()

    def visit(s, path):
        if s.name in done:
            return
        if s.name in path:
            raise ValueError(f"stage cycle through {s.name!r}")
        for n in s.inputs_declared:
            if n in producer:
                visit(producer[n], path | {s.name})
        done.add(s.name)
        order.append(s)

    for s in sorted(decl, key=lambda s: s.inputs is not None):
        visit(s, frozenset())
    return tuple(order)


def by_gives() -> dict:
    """{artifact: the stage producing it}."""
    return {s.gives: s for s in stages()}


def aliases() -> dict:
    """{other output name: artifact} (``Stage.aliases``)."""
    return {a: s.gives for s in stages() for a in s.aliases}


def scene_outputs() -> tuple[str, ...]:
    """The names a scene's [outputs] want may use (``Stage.scene_output`` and ``Stage.aliases``)."""
    return tuple(n for s in stages() for n in ((s.gives,) if s.scene_output else ()) + s.aliases)
