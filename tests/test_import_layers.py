"""No import runs back up: the package's import graph against its declared layer order.

The graph is read from the sources (``ast``), function-local imports included, so an
import hidden inside a function counts like one at the top of a file. Each module
belongs to the first layer whose prefix names it (longest prefix wins); a module may
import its own layer or any layer below, never one above. The only circle allowed is the
optional Dask plug-in's (the executor installs the plug-in, the plug-in calls back into
the executor on the worker). docs/architecture.md draws the same layers.
"""

from __future__ import annotations

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "tanbench"

# lowest first; a module's layer is its longest matching prefix
LAYERS: list[tuple[str, tuple[str, ...]]] = [
    ("base", ("tanbench", "tanbench.errors", "tanbench.earth", "tanbench.kernel_cache", "tanbench.paperdata")),
    # the metric declarations are specs too: names, types and rules, read by the schema
    ("specs", ("tanbench.options", "tanbench.config", "tanbench.profiles", "tanbench.sweep", "tanbench.schema",
               "tanbench.metrics.declarations")),
    ("world", ("tanbench.vehicle", "tanbench.terrain")),
    ("sensors", ("tanbench.sensors",)),
    ("navigation", ("tanbench.navigation",)),
    ("filters", ("tanbench.filters",)),
    ("simulation", ("tanbench.simulation",)),
    ("bounds", ("tanbench.bounds",)),
    ("metrics", ("tanbench.metrics", "tanbench.scoring")),
    ("methods", ("tanbench.methods",)),
    ("store", ("tanbench.store", "tanbench.results", "tanbench.check", "tanbench.claims",
               "tanbench.criterion")),
    ("runner", ("tanbench.runner",)),
    ("missions", ("tanbench.missions",)),
    ("analysis", ("tanbench.suitability", "tanbench.prediction", "tanbench.plot", "tanbench.anatomy",
                  "tanbench.paper", "tanbench.fit", "tanbench.report", "tanbench.bench", "tanbench.testing")),
    ("cli", ("tanbench.cli", "tanbench.__main__")),
]
ALLOWED_CIRCLES = [{"tanbench.runner.executors", "tanbench.runner.dask_plugin"}]


def module_files() -> dict[str, Path]:
    """Dotted module name -> source file, for every module of the package."""
    out = {}
    for path in PACKAGE.rglob("*.py"):
        parts = list(path.relative_to(PACKAGE.parent).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = path
    return out


def _owner(name: str, modules: dict[str, Path]) -> str:
    while name and name not in modules:
        name = name.rpartition(".")[0]
    return name


def import_graph() -> dict[str, set[str]]:
    """Module -> the package modules it imports anywhere in its source (top level or in a function)."""
    modules = module_files()
    graph: dict[str, set[str]] = {}
    for name, path in modules.items():
        package = name if path.name == "__init__.py" else name.rpartition(".")[0]
        targets = set()
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.Import):
                targets.update(_owner(a.name, modules) for a in node.names if a.name.startswith("tanbench"))
            elif isinstance(node, ast.ImportFrom):
                if node.level:
                    base = package.split(".")[: len(package.split(".")) - node.level + 1]
                    source = ".".join(base + ([node.module] if node.module else []))
                else:
                    source = node.module or ""
                if source.split(".")[0] != "tanbench":
                    continue
                for alias in node.names:
                    sub = f"{source}.{alias.name}"
                    targets.add(sub if sub in modules else _owner(source, modules))
        graph[name] = targets - {name, ""}
    return graph


def layer_of(module: str) -> int:
    best, best_len = None, -1
    for index, (_, prefixes) in enumerate(LAYERS):
        for prefix in prefixes:
            if (module == prefix or module.startswith(prefix + ".")) and len(prefix) > best_len:
                best, best_len = index, len(prefix)
    assert best is not None, f"{module} is in no declared layer: add it to LAYERS"
    return best


def test_every_module_has_a_layer():
    for module in module_files():
        layer_of(module)


def test_no_import_runs_back_up():
    upward = [f"{a} ({LAYERS[layer_of(a)][0]}) imports {b} ({LAYERS[layer_of(b)][0]})"
              for a, targets in sorted(import_graph().items()) for b in sorted(targets)
              if layer_of(b) > layer_of(a)]
    assert not upward, "imports that run back up:\n" + "\n".join(upward)


def strongly_connected(graph: dict[str, set[str]]) -> list[set[str]]:
    """Tarjan's strongly connected components with more than one module."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[set[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in graph.get(v, ()):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = set()
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.add(w)
                if w == v:
                    break
            if len(component) > 1:
                found.append(component)

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return found


def test_at_most_the_dask_circle():
    circles = strongly_connected(import_graph())
    extra = [sorted(c) for c in circles if c not in ALLOWED_CIRCLES]
    assert not extra, f"import circles: {extra}"


# where a function-local tanbench import is still allowed: the CLI (each command imports what it
# needs) and the executors (numpy only after a worker's thread limits; the Dask plug-in)
LOCAL_IMPORTS_ALLOWED = {"tanbench/cli.py", "tanbench/runner/executors.py", "tanbench/runner/dask_plugin.py"}


def test_function_local_imports_only_where_allowed():
    found = []
    for path in sorted(PACKAGE.rglob("*.py")):
        rel = path.relative_to(PACKAGE.parent).as_posix()
        if rel in LOCAL_IMPORTS_ALLOWED:
            continue
        for func in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(func, (ast.FunctionDef, ast.AsyncFunctionDef)):
                found += [f"{rel}:{node.lineno} {node.module}" for node in ast.walk(func)
                          if isinstance(node, ast.ImportFrom) and (node.module or "").startswith("tanbench")]
    assert not found, "function-local imports (import at the top instead):\n" + "\n".join(found)
