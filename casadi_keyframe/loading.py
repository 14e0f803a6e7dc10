"""Find and build problem files: Python files in ``problems/`` with ``build(**overrides)``."""
from __future__ import annotations

import importlib.util
import inspect
import os
from pathlib import Path

from .problem import ControlProblem


def problems_dir() -> Path:
    """The folder of problem files (``$CASADI_KEYFRAME_PROBLEMS`` or the repo's ``problems/``)."""
    env = os.environ.get("CASADI_KEYFRAME_PROBLEMS")
    return Path(env) if env else Path(__file__).resolve().parent.parent / "problems"


def list_problems() -> list[tuple[str, str]]:
    """``(name, first docstring line)`` of every problem file."""
    out = []
    for path in sorted(problems_dir().glob("*.py")):
        if path.name.startswith("_"):
            continue
        doc = (_module(path).__doc__ or "").strip().splitlines()
        out.append((path.stem, doc[0] if doc else ""))
    return out


def resolve(problem: str | os.PathLike) -> Path:
    """A problem file path from a path or a bare name such as ``flock_path``."""
    path = Path(problem)
    if path.suffix == ".py" and path.exists():
        return path
    candidate = problems_dir() / f"{path.stem}.py"
    if candidate.exists():
        return candidate
    names = ", ".join(n for n, _ in list_problems())
    raise FileNotFoundError(f"no problem file {problem!r}; known problems: {names}")


def load_module(problem):
    return _module(resolve(problem))


def load_problem(problem, **overrides) -> ControlProblem:
    """Build a problem from its file with keyword ``overrides`` (checked against ``build``)."""
    module = load_module(problem)
    build = getattr(module, "build", None)
    if build is None:
        raise AttributeError(f"{module.__file__} has no build(**overrides) function")
    params = inspect.signature(build).parameters
    accepts_any = any(p.kind is p.VAR_KEYWORD for p in params.values())
    unknown = sorted(set(overrides) - set(params))
    if unknown and not accepts_any:
        raise TypeError(f"unknown override(s) {unknown} for {Path(module.__file__).stem}; "
                        f"valid names: {sorted(params)}")
    prob = build(**overrides)
    if not isinstance(prob, ControlProblem):
        raise TypeError(f"{module.__file__}: build() must return a ControlProblem")
    return prob


def _module(path: Path):
    spec = importlib.util.spec_from_file_location(f"casadi_keyframe_problem_{path.stem}", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module
