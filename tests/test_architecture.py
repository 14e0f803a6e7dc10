"""The package's layout rules, read from its source with :mod:`ast`: no import cycles between
its modules (a package's face, its ``__init__``, counts as a module like any other), no
private name (``_x``) imported from another module, and no module longer than a room should
be.

Run on its own: ``python -m pytest tests/test_architecture.py -q``.  Imports inside functions
count too (a lazy import is how a cycle hides).
"""
from __future__ import annotations

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "casadi_keyframe"
NAME = PACKAGE.name
MAX_LINES = 500


def modules(package: Path = PACKAGE) -> dict[str, Path]:
    """Dotted module name -> file, ``pkg.__init__`` as ``pkg``."""
    out = {}
    for path in sorted(package.rglob("*.py")):
        parts = list(path.relative_to(package.parent).with_suffix("").parts)
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


def imports(mods: dict[str, Path], name: str = NAME):
    """``{module: [(target module, imported name or None, line)]}`` within the package."""
    out = {}
    for module, path in mods.items():
        is_package = path.name == "__init__.py"
        found = []
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.Import):
                found += [(a.name, None, node.lineno) for a in node.names
                          if a.name.split(".")[0] == name]
            elif isinstance(node, ast.ImportFrom):
                target = _absolute(module, is_package, node)
                if target.split(".")[0] != name:
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


def import_graph(mods: dict[str, Path], name: str = NAME) -> dict[str, set[str]]:
    """Module -> the modules it imports, a package's face included (importing ``pkg`` runs
    ``pkg/__init__.py``, which imports what it re-exports)."""
    graph = {m: set() for m in mods}
    for m, found in imports(mods, name).items():
        graph[m].update(target for target, _, _ in found if target != m)
    return graph


def test_no_import_cycles():
    assert cycles(import_graph(modules())) == []


def test_a_cycle_through_a_package_face_is_seen(tmp_path):
    """The cycle the first architecture pass could not see: a package's face imports its
    submodule, which imports a module that imports the package."""
    files = {"pkg/__init__.py": "", "pkg/export/__init__.py": "from .scene import Scene\n",
             "pkg/export/scene.py": "from ..run import format_misses\nScene = 1\n",
             "pkg/run.py": "def format_misses():\n    from .export import Scene\n"}
    for rel, text in files.items():
        (tmp_path / rel).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / rel).write_text(text)
    mods = modules(tmp_path / "pkg")
    assert cycles(import_graph(mods, "pkg")) == [["pkg.export", "pkg.export.scene", "pkg.run"]]


def test_no_module_is_longer_than_a_room_should_be():
    long = {m: n for m, path in modules().items()
            if (n := len(path.read_text().splitlines())) > MAX_LINES}
    assert long == {}, f"split these modules along their jobs: {long}"


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


ROOT_MODULES = 16  # the package root holds the core; roles live in folders


def test_the_root_holds_at_most_sixteen_modules():
    root = sorted(p.name for p in PACKAGE.glob("*.py"))
    assert len(root) <= ROOT_MODULES, f"sort these by role into folders: {root}"


def test_one_evaluator_class():
    found = [f"{mods}:{node.name}" for mods, path in modules().items()
             for node in ast.walk(ast.parse(path.read_text()))
             if isinstance(node, ast.ClassDef) and "Evaluator" in node.name]
    assert found == ["casadi_keyframe.optimize.evaluator:Evaluator"], found


def _code_strings(path: Path) -> list[str]:
    """The string constants of a module's code (docstrings left out)."""
    tree = ast.parse(path.read_text())
    docs = {id(n.body[0].value) for n in ast.walk(tree)
            if isinstance(n, (ast.Module, ast.ClassDef, ast.FunctionDef))
            and n.body and isinstance(n.body[0], ast.Expr)
            and isinstance(n.body[0].value, ast.Constant)}
    return [n.value for n in ast.walk(tree) if isinstance(n, ast.Constant)
            and isinstance(n.value, str) and id(n) not in docs]


def test_no_route_is_known_by_name_in_the_health_modules():
    from casadi_keyframe.adjoints import ROUTES

    for rel in ("health.py", "studies/health_report.py"):
        named = [s for s in _code_strings(PACKAGE / rel) if s in ROUTES]
        assert named == [], f"{rel} branches on route names {named}: ask the route object"


def test_export_formats_go_through_one_table():
    tree = ast.parse((PACKAGE / "export" / "__init__.py").read_text())
    chains = [n.lineno for n in ast.walk(tree) if isinstance(n, ast.If)
              and len(n.orelse) == 1 and isinstance(n.orelse[0], ast.If)]
    assert chains == [], f"export/__init__.py has an elif chain at lines {chains}: a table"


def test_the_collision_choices_are_written_once():
    from casadi_keyframe.models import COLLISIONS

    here = PACKAGE / "models" / "contact" / "collisions.py"
    files = [p for p in PACKAGE.rglob("*.py") if p != here]
    files += sorted((PACKAGE.parent / "problems").glob("*.py"))
    written = [f"{p.name}: {s!r}" for p in files for s in _code_strings(p) if s in COLLISIONS
               and s != "guarded"]  # a problem may name one choice; never list them again
    tuples = [f"{p.name}:{n.lineno}" for p in files for n in ast.walk(ast.parse(p.read_text()))
              if isinstance(n, (ast.Tuple, ast.List)) and len(n.elts) > 1
              and {getattr(e, "value", None) for e in n.elts} <= set(COLLISIONS)]
    assert tuples == [], f"the collision choices listed again: {tuples}; use models.COLLISIONS"
    assert all("DEFAULT_COLLISION" not in w for w in written)


BODY_KINDS = {"plane", "round", "mesh"}  # the body shapes' old names (geometry's types now)


def kind_branches(source: str, names) -> list[int]:
    """The lines where ``source`` knows a kind by its name: a comparison with one of
    ``names`` written as a string (``kind == "plane"``, ``kind in ("round", "mesh")``), a
    ``match`` case on one, or a table keyed by one."""
    def named(node):
        if isinstance(node, ast.Constant):
            return node.value in names
        return isinstance(node, (ast.Tuple, ast.List, ast.Set)) and any(map(named, node.elts))

    lines = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Compare) and any(map(named, [node.left, *node.comparators])):
            lines.append(node.lineno)
        elif isinstance(node, ast.MatchValue) and named(node.value):
            lines.append(node.lineno)
        elif isinstance(node, ast.Dict) and any(k is not None and named(k) for k in node.keys):
            lines.append(node.lineno)
    return sorted(lines)


def _outputs() -> list[Path]:
    return sorted((PACKAGE / "render").glob("*.py")) + sorted((PACKAGE / "export").glob("*.py"))


def test_pictures_and_exports_know_no_body_kind_by_name():
    found = {p.relative_to(PACKAGE).as_posix(): lines for p in _outputs()
             if (lines := kind_branches(p.read_text(), BODY_KINDS))}
    assert found == {}, (f"branches on a body's kind by name {found}: ask its shape "
                         f"(geometry.BodyShape) or key a table by the shape's type")


def test_pictures_and_exports_know_no_marker_kind_by_name():
    from casadi_keyframe.objectives.markers import MARKER_KINDS

    found = {p.relative_to(PACKAGE).as_posix(): lines for p in _outputs()
             if (lines := kind_branches(p.read_text(), set(MARKER_KINDS)))}
    assert found == {}, (f"branches on a marker's kind by name {found}: ask its kind or key "
                         f"a table by its figure (objectives.markers.Figure)")


def test_the_kind_check_sees_a_branch_by_name():
    source = ('if body.kind == "plane":\n    pass\n'
              'x = [b for b in bodies if b.kind in ("round", "mesh")]\n'
              'TABLE = {"mesh": 1}\n'
              'match kind:\n    case "round":\n        pass\n'
              'ok = record.get("round") == before.get("round")\n')
    assert kind_branches(source, BODY_KINDS) == [1, 3, 4, 6]
