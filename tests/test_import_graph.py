"""The package's import graph, read from the source (ast): no cycles among its modules, and
every import runs down the levels (a lower level never imports a higher one), so the graph a
maintainer reads is the graph there is. Imports inside functions count as much as those at the
top of a module."""

from __future__ import annotations

import ast
from pathlib import Path

SRC = Path(__file__).resolve().parents[1] / "src" / "myoface"

#: the levels, lowest first: a module may import its own level's and lower levels' modules
LEVELS = (
    ("myoface.errors", "myoface._io", "myoface._threads", "myoface._signals", "myoface.facemesh"),
    ("myoface.face",),
    ("myoface.tissue", "myoface.muscles", "myoface.render"),
    ("myoface.model",),
    ("myoface.control",),
    ("myoface.synth",),
    ("myoface.analysis",),
    ("myoface.export",),
    ("myoface.codec",),
    ("myoface.viewer",),
    ("myoface.bench",),
    ("myoface.commands",),
    ("myoface.cli", "myoface.__main__"),
)


def _module_name(path: Path) -> str:
    rel = path.relative_to(SRC.parent).with_suffix("")
    parts = list(rel.parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def _imports(path: Path, name: str) -> set[str]:
    """The myoface modules ``path`` imports (absolute and relative, anywhere in the file)."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    out: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out |= {a.name for a in node.names if a.name.startswith("myoface")}
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[: len(base) - node.level + 1]
                mod = ".".join(base + ([node.module] if node.module else []))
            else:
                mod = node.module or ""
            if mod.startswith("myoface"):
                out.add(mod)
                # ``from myoface.analysis import pipeline`` imports a module, not a name
                out |= {f"{mod}.{a.name}" for a in node.names}
    return out


def _graph() -> dict[str, set[str]]:
    files = {_module_name(p): p for p in SRC.rglob("*.py")}
    graph = {}
    for name, path in files.items():
        graph[name] = {m for m in _imports(path, name) if m in files and m != name}
    return graph


def _level(module: str) -> int:
    if module == "myoface":
        return -1  # the package's front door, which imports on first use (see below)
    for k, prefixes in enumerate(LEVELS):
        if any(module == p or module.startswith(p + ".") for p in prefixes):
            return k
    raise AssertionError(f"{module} is in no level of LEVELS: add it")


def test_every_module_has_a_level():
    for module in _graph():
        _level(module)


def test_imports_run_down_the_levels():
    """A module imports only modules of its own level or lower (the package's ``__init__``,
    which imports the user's handful of names lazily, aside)."""
    upward = sorted(
        f"{a} -> {b}"
        for a, targets in _graph().items()
        if a != "myoface"
        for b in targets
        if b != "myoface" and _level(b) > _level(a)
    )
    assert not upward, "imports up the levels:\n" + "\n".join(upward)


def test_no_import_cycles():
    """No module can reach itself through the imports of others."""
    cycles = _cycles(_graph())
    assert not cycles, "import cycles:\n" + "\n".join(" <-> ".join(c) for c in cycles)


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan 1972); a module's
    import of its own package (for a name its ``__init__`` re-exports) is not counted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    cycles: list[list[str]] = []
    counter = [0]

    def edges(v):
        # an import of a package means its __init__; a module's import of its own
        # package's __init__ (for a sibling name) is not a cycle through the package
        return [w for w in graph[v] if not v.startswith(w + ".")]

    def strong(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in edges(v):
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
                cycles.append(sorted(comp))

    import sys

    sys.setrecursionlimit(max(sys.getrecursionlimit(), 10000))
    for v in graph:
        if v not in index:
            strong(v)
    return cycles


def test_the_graph_is_read_from_the_source():
    """The reader finds what a module imports, at the top and inside functions (so the two
    tests above can fail)."""
    graph = _graph()
    assert "myoface.errors" in graph["myoface.analysis.camera"]
    assert "myoface.analysis.trackers.base" in graph["myoface.analysis.trackers.snakes"]
    assert _level("myoface.cli") > _level("myoface.analysis.pipeline") > _level("myoface.face")
    a, b, c = "myoface.a", "myoface.b", "myoface.c"
    assert _cycles({a: {b}, b: {c}, c: {a}}) == [[a, b, c]]
    assert _cycles({a: {b}, b: {c}, c: set()}) == []
