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


def test_no_route_is_known_by_name_outside_the_registry():
    """A route is asked for its facts and passed as an object; its name is written in the
    adjoints' registry (each route's ``name``) and nowhere else in the package."""
    from casadi_keyframe.adjoints import GRADIENTS

    registry = PACKAGE / "adjoints"
    named = [f"{p.relative_to(PACKAGE)}: {s!r}" for p in sorted(PACKAGE.rglob("*.py"))
             if registry not in p.parents for s in _code_strings(p) if s in GRADIENTS]
    assert named == [], f"route names written outside the registry: {named}"


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


def clock_reads(tree) -> list[int]:
    """The lines of ``time.X()`` calls (and of calls of names imported from ``time``)."""
    imported = {alias.asname or alias.name for node in ast.walk(tree)
                if isinstance(node, ast.ImportFrom) and node.module == "time"
                for alias in node.names}
    return [node.lineno for node in ast.walk(tree) if isinstance(node, ast.Call) and (
        (isinstance(node.func, ast.Attribute) and isinstance(node.func.value, ast.Name)
         and node.func.value.id == "time")
        or (isinstance(node.func, ast.Name) and node.func.id in imported))]


def test_the_optimizer_reads_the_clock_only_through_its_deadline():
    """One deadline: no ``time.*()`` call in optimize/ outside its deadline module (a stage,
    a method or the finish asks the Deadline it is handed; a time is read with its now())."""
    clock = PACKAGE / "optimize" / "deadline.py"
    found = [f"{p.relative_to(PACKAGE)}:{line}"
             for p in sorted((PACKAGE / "optimize").rglob("*.py")) if p != clock
             for line in clock_reads(ast.parse(p.read_text()))]
    assert found == [], f"clock read outside optimize/deadline.py: {found}"
    sample = ast.parse("import time\nfrom time import perf_counter as pc\n"
                       "t = time.perf_counter()\nu = pc()\n")
    assert clock_reads(sample) == [3, 4]


def written_defaults(tree, defaults: dict) -> list[int]:
    """The lines where a name of ``defaults`` is given its default value: a parameter's
    default, a dict's entry, a call's keyword."""
    def same(name, node):
        return (name in defaults and isinstance(node, ast.Constant)
                and type(node.value) is type(defaults[name]) and node.value == defaults[name])

    found = []
    for node in ast.walk(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda)):
            a = node.args
            pairs = list(zip(a.args[len(a.args) - len(a.defaults):], a.defaults))
            pairs += [(k, d) for k, d in zip(a.kwonlyargs, a.kw_defaults) if d is not None]
            found += [d.lineno for arg, d in pairs if same(arg.arg, d)]
        elif isinstance(node, ast.Dict):
            found += [v.lineno for k, v in zip(node.keys, node.values)
                      if isinstance(k, ast.Constant) and same(k.value, v)]
        elif isinstance(node, ast.Call):
            found += [kw.value.lineno for kw in node.keywords if same(kw.arg, kw.value)]
    return found


def test_the_solve_requests_defaults_are_written_once():
    """Every default of a solve request is a field of SolveSettings (optimize/settings.py):
    no function of the package takes a setting with its default value of its own, no dict
    or call writes it again (the default route is the registry's: see the route names)."""
    from dataclasses import fields

    from casadi_keyframe.optimize.settings import SolveSettings

    defaults = {f.name: f.default for f in fields(SolveSettings)
                if f.default is not None and not isinstance(f.default, bool)}
    assert set(defaults) == {"method", "maxiter", "tol"}
    settings = PACKAGE / "optimize" / "settings.py"
    found = [f"{p.relative_to(PACKAGE)}:{line}" for p in sorted(PACKAGE.rglob("*.py"))
             if p != settings for line in written_defaults(ast.parse(p.read_text()), defaults)]
    assert found == [], f"a solve default written again: {found}"
    sample = ast.parse('def solve(p, method="lbfgsb", *, tol=1e-8, maxiter=10):\n'
                       '    return run(p, maxiter=200, **{"method": "ipopt"})\n')
    assert written_defaults(sample, defaults) == [1, 1, 2]


def test_the_evaluators_bookkeeping_is_kept_by_the_evaluator_alone():
    """Evaluations, failures and their seconds are counted in one place: no other class of
    optimize/ keeps them (the finish judges its trials through the Evaluator)."""
    counters = {"nfev", "failures", "seconds"}
    evaluator = PACKAGE / "optimize" / "evaluator.py"
    kept = [f"{p.relative_to(PACKAGE)}:{node.lineno}"
            for p in sorted((PACKAGE / "optimize").rglob("*.py")) if p != evaluator
            for node in ast.walk(ast.parse(p.read_text()))
            if isinstance(node, ast.Attribute) and isinstance(node.ctx, ast.Store)
            and isinstance(node.value, ast.Name) and node.value.id == "self"
            and node.attr in counters]
    assert kept == [], f"the evaluator's bookkeeping kept again: {kept}"


def test_the_optimizers_face_names_every_module():
    """optimize/__init__.py's docstring is the wing's map: it names each of its modules and
    folders (the drift the third pass left: 12 of 21 named)."""
    import casadi_keyframe.optimize as optimize

    rooms = sorted({p.stem for p in (PACKAGE / "optimize").glob("*.py")} - {"__init__"}
                   | {p.name for p in (PACKAGE / "optimize").iterdir()
                      if p.is_dir() and (p / "__init__.py").is_file()})
    unnamed = [room for room in rooms if f":mod:`.{room}`" not in optimize.__doc__]
    assert unnamed == [], f"optimize/__init__.py does not name {unnamed}"
