"""The package's layout rules, read from its source with :mod:`ast`: no import cycles between
its modules, and no private name (``_x``) imported from another module.

Run on its own: ``python -m pytest tests/test_architecture.py -q``.  Imports inside functions
count too (a lazy import is how a cycle hides).
"""
from __future__ import annotations

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "casadi_keyframe"
NAME = PACKAGE.name


def modules() -> dict[str, Path]:
    """Dotted module name -> file, ``pkg.__init__`` as ``pkg``."""
    out = {}
    for path in sorted(PACKAGE.rglob("*.py")):
        parts = list(path.relative_to(PACKAGE.parent).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts.pop()
        out[".".join(parts)] = path
    return out


def _absolute(module: str, is_package: bool, node: ast.ImportFrom) -> str:
    if not node.level:
        return node.module or ""
    base = module.split(".")
    base = base if is_package else base[:-1]
    base = base[:len(base) - (node.level - 1)]
    return ".".join(base + ([node.module] if node.module else []))


def imports(mods: dict[str, Path]):
    """``{module: [(target module, imported name or None, line)]}`` within the package."""
    out = {}
    for module, path in mods.items():
        is_package = path.name == "__init__.py"
        found = []
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.Import):
                found += [(a.name, None, node.lineno) for a in node.names
                          if a.name.split(".")[0] == NAME]
            elif isinstance(node, ast.ImportFrom):
                target = _absolute(module, is_package, node)
                if target.split(".")[0] != NAME:
                    continue
                for alias in node.names:
                    sub = f"{target}.{alias.name}"
                    if sub in mods:  # ``from . import submodule``
                        found.append((sub, None, node.lineno))
                    else:
                        found.append((target, alias.name, node.lineno))
        out[module] = [(t, n, line) for t, n, line in found if t in mods]
    return out


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan)."""
    index, low, stack, on, out = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in graph.get(v, ()):
            if w not in index:
                visit(w)
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

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def _package_of(module: str, mods) -> str:
    return module if mods[module].name == "__init__.py" else module.rsplit(".", 1)[0]


def test_no_import_cycles():
    mods = modules()
    graph = {m: set() for m in mods}
    for m, found in imports(mods).items():
        for target, _, _ in found:
            # a package's face importing its own submodules is not a cycle
            if target != m and not (mods[m].name == "__init__.py" and target.startswith(m + ".")):
                graph[m].add(target)
    assert cycles(graph) == []


def test_no_private_names_imported_across_modules():
    mods = modules()
    bad = [f"{mods[m].relative_to(PACKAGE.parent)}:{line} imports {name} from {target}"
           for m, found in imports(mods).items() for target, name, line in found
           if name and name.startswith("_") and not name.startswith("__") and target != m]
    assert bad == []


def test_the_checks_see_a_cycle_and_a_private_import():
    assert cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    tree = ast.parse("from .render import _legend")
    node = tree.body[0]
    assert _absolute(f"{NAME}.render_blend", False, node) == f"{NAME}.render"
