"""No import cycle among the project's modules (the graph built with ``ast`` from every ``.py`` of
the packages). Module-level imports (run when the module is imported: the body, class bodies,
``if``/``try`` blocks; not ``if TYPE_CHECKING:``) must form no cycle. Imports inside functions run
later and could close a loop without harm to import order; ``function_level_cycles`` lists those,
and there must be none either."""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("userio", "bridge", "flexure", "calibration", "estimator", "torquebench")


def modules() -> dict[str, Path]:
    """{dotted name: file} of every module of the packages (a package is its ``__init__``)."""
    out = {}
    for pkg in PACKAGES:
        for f in sorted((ROOT / pkg).rglob("*.py")):
            parts = list(f.relative_to(ROOT).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts.pop()
            out[".".join(parts)] = f
    return out


def _is_type_checking(node: ast.If) -> bool:
    t = node.test
    return (isinstance(t, ast.Name) and t.id == "TYPE_CHECKING") or \
        (isinstance(t, ast.Attribute) and t.attr == "TYPE_CHECKING")


def _targets(node, name: str, is_pkg: bool, known) -> set[str]:
    """Project modules an import statement in module ``name`` loads."""
    out = set()
    if isinstance(node, ast.Import):
        for a in node.names:
            if a.name in known:
                out.add(a.name)
        return out
    base = node.module or ""
    if node.level:                                  # relative: from the module's package
        pkg = name.split(".") if is_pkg else name.split(".")[:-1]
        pkg = pkg[:len(pkg) - (node.level - 1)]
        base = ".".join(pkg + ([base] if base else []))
    for a in node.names:
        full = f"{base}.{a.name}"
        if full in known:
            out.add(full)                           # from pkg import submodule
        elif base in known:
            out.add(base)
    return out


def import_graph() -> tuple[dict, dict]:
    """({module: {modules its module-level imports load}}, {module: {... its function-level ones}})."""
    known = modules()
    top, inner = {m: set() for m in known}, {m: set() for m in known}

    def walk(nodes, name, is_pkg, in_function):
        for node in nodes:
            if isinstance(node, (ast.Import, ast.ImportFrom)):
                (inner if in_function else top)[name] |= _targets(node, name, is_pkg, known) - {name}
            elif isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda)):
                walk(ast.iter_child_nodes(node), name, is_pkg, True)
            elif isinstance(node, ast.If) and _is_type_checking(node):
                walk(node.orelse, name, is_pkg, in_function)
            else:
                walk(ast.iter_child_nodes(node), name, is_pkg, in_function)

    for name, f in known.items():
        walk(ast.parse(f.read_text(), str(f)).body, name, f.name == "__init__.py", False)
    return top, inner


def cycles(graph: dict) -> list[list[str]]:
    """The strongly connected components with more than one module (Tarjan), each sorted."""
    index, low, stack, on, out = {}, {}, [], set(), []
    counter = [0]

    def strong(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in sorted(graph.get(v, ())):
            if w not in index:
                strong(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    import sys

    limit = sys.getrecursionlimit()
    sys.setrecursionlimit(max(limit, 10 * len(graph) + 100))
    try:
        for v in sorted(graph):
            if v not in index:
                strong(v)
    finally:
        sys.setrecursionlimit(limit)
    return sorted(out)


def function_level_cycles() -> list[list[str]]:
    """Cycles that need a function-level import to close (listed, not failed)."""
    top, inner = import_graph()
    both = {m: top[m] | inner[m] for m in top}
    return [c for c in cycles(both) if c not in cycles(top)]


def test_the_graph_sees_the_projects_imports():
    top, inner = import_graph()
    assert "torquebench.scene_views" in top["torquebench.stages.report"]     # module level
    assert "estimator.estimate" in inner["torquebench.stages.estimates"]    # inside a stage
    assert cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]


def test_no_module_level_import_cycle():
    top, _ = import_graph()
    found = cycles(top)
    assert not found, "module-level import cycles: " + "; ".join(" ↔ ".join(c) for c in found)


def test_no_function_level_cycle():
    """No cycle even through the imports inside functions (the last two, a loader/dispatch pair in
    estimator.spatial and one in flexure's meshing, were cut when this became strict)."""
    new = function_level_cycles()
    assert not new, "import cycles through function-level imports: " + \
        "; ".join(" ↔ ".join(c) for c in new)


def test_the_estimators_modules_form_no_cycle_even_inside_functions():
    """The modules of ``estimator`` itself (not its sim/spatial subpackages), counting the imports
    inside functions too: each compiled loop sits beside the function it speeds up and imports
    only estimator.compiled; estimator.warmup, which runs them all, is imported by none."""
    top, inner = import_graph()
    own = {m for m in top if m == "estimator" or (m.startswith("estimator.") and m.count(".") == 1)}
    assert {"estimator.compiled", "estimator.warmup", "estimator.estimate"} <= own
    found = cycles({m: (top[m] | inner[m]) & own for m in own})
    assert not found, "estimator import cycles: " + "; ".join(" ↔ ".join(c) for c in found)
    assert not any("estimator.warmup" in inner[m] | top[m] for m in top)

