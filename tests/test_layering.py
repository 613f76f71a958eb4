"""The packages' layering, read from the source: no import circle anywhere (a lazy import
inside a function counts: it is a circle all the same, postponed), the env never imports
the calibrators, and the model below the instruments, the world and the lab imports none
of them."""

from __future__ import annotations

import ast
import functools
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PACKAGES = ("orthoglide_env", "calibrators")


def _module_name(path: Path, root: Path) -> str:
    parts = path.relative_to(root).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _is_alias(tree: ast.Module) -> bool:
    """An old import path kept for earlier scripts: it replaces itself with its new module
    in ``sys.modules`` and holds nothing of its own."""
    return any(isinstance(node, ast.Assign) and ast.unparse(node).startswith("sys.modules[")
               for node in tree.body)


def import_graph(root: Path = ROOT) -> dict[str, set[str]]:
    """Every project module (old paths' aliases left out) -> the project modules it imports,
    at any depth of its code; ``from package import name`` counts as an import of the
    submodule where ``name`` is one."""
    sources = {_module_name(p, root): p
               for package in PACKAGES for p in (root / package).rglob("*.py")}
    trees = {name: ast.parse(path.read_text()) for name, path in sources.items()}
    modules = {name for name, tree in trees.items() if not _is_alias(tree)}
    graph: dict[str, set[str]] = {}
    for name in modules:
        package = name if sources[name].name == "__init__.py" else name.rpartition(".")[0]
        edges: set[str] = set()
        for node in ast.walk(trees[name]):
            if isinstance(node, ast.Import):
                targets = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    anchor = package.split(".")[: len(package.split(".")) - node.level + 1]
                    base = ".".join(anchor + ([base] if base else []))
                targets = [f"{base}.{alias.name}" for alias in node.names] + [base]
            else:
                continue
            for target in targets:
                while target and target not in modules:
                    target = target.rpartition(".")[0]
                if target and target != name and not name.startswith(target + "."):
                    edges.add(target)
        graph[name] = edges
    return graph


def circles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan's algorithm)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    found: list[list[str]] = []

    def visit(node: str) -> None:
        index[node] = low[node] = len(index)
        stack.append(node)
        for nxt in sorted(graph.get(node, ())):
            if nxt not in index:
                visit(nxt)
                low[node] = min(low[node], low[nxt])
            elif nxt in stack:
                low[node] = min(low[node], index[nxt])
        if low[node] == index[node]:
            component = []
            while True:
                top = stack.pop()
                component.append(top)
                if top == node:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for node in sorted(graph):
        if node not in index:
            visit(node)
    return found


@functools.cache
def tree_graph() -> dict[str, set[str]]:
    """:func:`import_graph` of this tree, read once per process (every source parsed):
    the tests below read it and change nothing."""
    return import_graph()


def test_no_import_circle() -> None:
    assert circles(tree_graph()) == []


def test_the_walk_finds_a_circle_that_is_added(tmp_path) -> None:
    """The test above can fail: a copy of the tree with one import added back from the
    model to the lab has a circle, and the walk names it."""
    for package in PACKAGES:
        for path in (ROOT / package).rglob("*.py"):
            copy = tmp_path / path.relative_to(ROOT)
            copy.parent.mkdir(parents=True, exist_ok=True)
            copy.write_text(path.read_text())
    kinematics = tmp_path / "orthoglide_env" / "model" / "kinematics.py"
    kinematics.write_text(kinematics.read_text() + "\n\ndef _late():\n"
                          "    from orthoglide_env.lab import engine  # noqa: F401\n")
    found = circles(import_graph(tmp_path))
    assert any({"orthoglide_env.model.kinematics", "orthoglide_env.lab.engine"} <= set(c)
               for c in found)


def test_layers() -> None:
    """Who may import whom: the env never the calibrators; the model (geometry and
    kinematics) none of the instruments, the world, the lab, the simulator or the envs;
    the instruments and the world not the lab, the envs or the reading model above them."""
    graph = tree_graph()
    above = {
        "orthoglide_env": ("calibrators",),
        "orthoglide_env.model": ("orthoglide_env.instruments", "orthoglide_env.world",
                                 "orthoglide_env.lab", "orthoglide_env.sim",
                                 "orthoglide_env.envs", "orthoglide_env.reading_model",
                                 "orthoglide_env.scoring"),
        "orthoglide_env.instruments": ("orthoglide_env.lab", "orthoglide_env.envs",
                                       "orthoglide_env.reading_model"),
        "orthoglide_env.world": ("orthoglide_env.lab", "orthoglide_env.envs",
                                 "orthoglide_env.reading_model"),
    }
    wrong = sorted(f"{name} imports {target}" for name, targets in graph.items()
                   for layer, banned in above.items()
                   if name == layer or name.startswith(layer + ".")
                   for target in targets
                   if any(target == b or target.startswith(b + ".") for b in banned))
    assert wrong == []


def test_old_import_paths_are_the_moved_modules() -> None:
    """Earlier scripts' imports keep working, and give the module itself, not a copy whose
    state (registries, caches) would drift from the one the package uses."""
    import importlib

    # The packages' own folders walked, not the whole tree (a clone's .venv holds
    # thousands of files).
    moved = {old: _alias_target(path) for package in PACKAGES
             for path in (ROOT / package).rglob("*.py")
             if _is_alias(ast.parse(path.read_text()))
             for old in [_module_name(path, ROOT)]}
    assert "calibrators.experiment" in moved
    for old, new in moved.items():
        assert importlib.import_module(old) is importlib.import_module(new), old


def _alias_target(path: Path) -> str:
    """The module an old path's file stands for (its ``from PACKAGE import MODULE``)."""
    node = next(n for n in ast.parse(path.read_text()).body if isinstance(n, ast.ImportFrom))
    return f"{node.module}.{node.names[0].name}"
