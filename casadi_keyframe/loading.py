"""Find, check and build problem files: Python files in ``problems/`` with ``build(**overrides)``.

Overrides are checked before ``build`` runs, so a bad value is refused by name instead of
failing somewhere inside the problem's arithmetic.  The type of each keyword comes from its
annotation in ``build`` (``int``, ``float``, ``str``, ``bool``, ``X | None``,
``tuple[float, ...]``; unannotated keywords take their default's type), and its allowed values
from the problem file's module-level ``RANGES``: an interval in mathematical notation for a
number (``"[1, inf)"``, ``"(0, inf)"``, ``"[2, 3]"``) or a tuple of the allowed strings.
"""
from __future__ import annotations

import difflib
import importlib.util
import inspect
import numbers
import os
import re
import typing
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .problem import ControlProblem
from .state import SimulationError


class OverrideError(ValueError):
    """An override that ``build`` does not take, of the wrong type or out of its range
    (``listed``: ``show`` lists what it takes), or whose value ``build`` itself refuses (a
    file that cannot be a cloth: ``listed`` False)."""

    def __init__(self, message: str, problem: str, *, listed: bool = True):
        super().__init__(message)
        self.problem, self.listed = problem, listed


@dataclass(frozen=True)
class Override:
    """One keyword of a problem's ``build``: ``kind`` is ``"int"``, ``"float"``, ``"str"``,
    ``"bool"``, ``"floats"`` (a tuple of ``length`` numbers) or ``"any"``; ``allowed`` is an
    interval such as ``"[1, inf)"``, a tuple of strings, or None (any value of the kind)."""
    name: str
    kind: str
    default: object
    optional: bool = False
    length: int | None = None
    allowed: str | tuple | None = None

    @property
    def type_name(self) -> str:
        base = (f"{self.length or 'some'} floats" if self.kind == "floats" else self.kind)
        return base + (" | None" if self.optional else "")

    def describe(self) -> str:
        """``"an integer in [1, inf)"``, ``"one of 'smooth', 'hard'"``, ...: what it must be."""
        if isinstance(self.allowed, tuple):
            what = "one of " + ", ".join(repr(a) for a in self.allowed)
        else:
            what = {"int": "an integer", "float": "a number", "str": "a string",
                    "bool": "True or False", "any": "any value",
                    "floats": f"{self.length or 'some'} numbers"}[self.kind]
            what += f" in {self.allowed}" if self.allowed else ""
        return what + (" or None" if self.optional else "")


def problems_dir() -> Path:
    """The folder of problem files (``$CASADI_KEYFRAME_PROBLEMS`` or the repo's ``problems/``)."""
    env = os.environ.get("CASADI_KEYFRAME_PROBLEMS")
    return Path(env) if env else Path(__file__).resolve().parent.parent / "problems"


def list_problems() -> list[tuple[str, str]]:
    """``(name, first sentence of the docstring)`` of every problem file; a file that fails
    to import is listed with why, so one broken file does not hide the others."""
    out = []
    for path in sorted(problems_dir().glob("*.py")):
        if path.name.startswith("_"):
            continue
        try:
            out.append((path.stem, first_sentence(_module(path).__doc__ or "")))
        except ValueError as err:
            out.append((path.stem, f"(cannot be loaded: {err})"))
    return out


def first_sentence(text: str) -> str:
    """The first sentence of a docstring's first paragraph, on one line ("Fig. 3: ..." and
    "e.g. x" do not end it: a sentence ends at ". " followed by a capital letter)."""
    paragraph = " ".join(inspect.cleandoc(text).split("\n\n")[0].split())
    return re.split(r"(?<=[.!?])\s+(?=[A-Z])", paragraph)[0]


def resolve(problem: str | os.PathLike) -> Path:
    """A problem file from a bare name such as ``flock_path`` (looked up in
    :func:`problems_dir`) or a path, which must exist (a name with a folder part or a
    suffix is a path: ``/tmp/flock_path.py`` never falls back to ``problems/flock_path.py``)."""
    text = os.fspath(problem)
    path = Path(text)
    is_path = (os.sep in text or (os.altsep and os.altsep in text) or bool(path.suffix)
               or text in (".", ".."))
    if not is_path:
        candidate = problems_dir() / f"{text}.py"
        if candidate.is_file():
            return candidate
        names = ", ".join(n for n, _ in list_problems())
        close = difflib.get_close_matches(text, [n for n, _ in list_problems()], n=1)
        hint = f" (did you mean {close[0]}?)" if close else ""
        raise FileNotFoundError(f"no problem named {text!r}{hint}; known problems: {names}; "
                                f"or give the path to a problem file")
    if not path.exists():
        raise FileNotFoundError(f"problem file {text} does not exist; give an existing .py "
                                f"file, or a bare name such as {path.stem} for a file in "
                                f"{problems_dir()}")
    if path.is_dir() or path.suffix != ".py":
        raise FileNotFoundError(f"{text} is not a problem file: give a Python file (.py) "
                                f"that defines build(**overrides)")
    return path


def load_module(problem):
    """The problem file's module (executed afresh)."""
    return _module(resolve(problem))


def overrides_of(module) -> list[Override]:
    """Every keyword of the module's ``build`` with its type, default and allowed values."""
    name = _name(module)
    build = getattr(module, "build", None)
    if not callable(build):
        raise ValueError(f"{module.__file__} has no build(**overrides) function; a problem "
                         f"file defines build(...) returning a ControlProblem")
    ranges = dict(getattr(module, "RANGES", {}))
    try:
        signature = inspect.signature(build, eval_str=True)
    except Exception:  # an annotation that does not evaluate: such keywords take any value
        signature = inspect.signature(build)
    params = {p.name: p for p in signature.parameters.values()
              if p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY)}
    stray = sorted(set(ranges) - set(params))
    if stray:
        raise ValueError(f"{module.__file__}: RANGES names {stray}, which build() does not take")
    return [_override(name, p, ranges.get(p.name)) for p in params.values()]


def check_overrides(module, overrides: dict) -> dict:
    """``overrides`` checked against the module's ``build`` and ``RANGES`` and converted
    (``10.0`` to ``10`` for an int, a list to a tuple of floats); :class:`OverrideError`
    naming every bad one, its type, range and default."""
    name = _name(module)
    known = {o.name: o for o in overrides_of(module)}
    params = inspect.signature(module.build).parameters.values()
    accepts_any = any(p.kind is p.VAR_KEYWORD for p in params)
    unknown = sorted(set(overrides) - set(known))
    if unknown and not accepts_any:
        named = [u + "".join(f" (did you mean {c}?)"
                             for c in difflib.get_close_matches(u, known, n=1)) for u in unknown]
        raise OverrideError(f"{name}: unknown override {', '.join(named)}; valid names: "
                            f"{', '.join(known)}", name)
    out, errors = {}, []
    for key, value in overrides.items():
        spec = known.get(key)
        try:
            out[key] = value if spec is None else _check(spec, value)
        except (ValueError, TypeError):
            errors.append(f"{key} must be {spec.describe()} (default {spec.default!r}), "
                          f"got {value!r}")
    if errors:
        raise OverrideError(f"{name}: " + "; ".join(errors), name)
    return out


def load_problem(problem, **overrides) -> ControlProblem:
    """Build a problem from its file with keyword ``overrides``, checked first by
    :func:`check_overrides`."""
    return build_problem(load_module(problem), **overrides)


@dataclass(frozen=True)
class ProblemSource:
    """Where a problem came from: its loaded problem file and the overrides it was built with."""

    module: object
    overrides: dict

    def build(self, **more) -> ControlProblem:
        """The problem built again with ``more`` overrides over the ones it had."""
        return build_problem(self.module, **{**self.overrides, **more})


def build_problem(module, **overrides) -> ControlProblem:
    """The problem of an already loaded problem file, ``overrides`` checked first; it can be
    rebuilt with more overrides (its :class:`ProblemSource`,
    :meth:`ControlProblem.at_resolution`)."""
    checked = check_overrides(module, overrides)
    try:
        prob = module.build(**checked)
    except (SimulationError, OverrideError):  # a warm start that blows up; a bad override
        raise  # that build() itself refuses by the option's name: the user's input, not a bug
    except Exception as err:  # noqa: BLE001 - the user's code: any error, reported by line
        raise ProblemFileError(module.__file__, "in build()", err) from err
    if not isinstance(prob, ControlProblem):
        raise TypeError(f"{module.__file__}: build() must return a ControlProblem")
    return prob.with_source(ProblemSource(module, dict(overrides)))


def solve_defaults(module, overrides: dict | None = None) -> dict:
    """How the problem file asks to be solved: its ``SOLVE``, a dict of solve settings (the
    names :class:`~casadi_keyframe.optimize.SolveSettings` takes; what it leaves out is the
    library's default).  ``SOLVE`` may also be a function of ``build``'s keyword values
    returning that dict (a problem solved one way from one start and another from another);
    it gets the defaults with ``overrides`` over them."""
    solve = getattr(module, "SOLVE", {})
    if callable(solve):
        values = {o.name: o.default for o in overrides_of(module)}
        solve = solve(**{**values, **(overrides or {})})
    return dict(solve)


_INTERVAL = re.compile(r"^\s*([\[(])\s*([^,\s]+)\s*,\s*([^,\s]+)\s*([\])])\s*$")


def _override(problem: str, param: inspect.Parameter, allowed) -> Override:
    """The :class:`Override` of one ``build`` parameter, its annotation read as a type."""
    default = None if param.default is param.empty else param.default
    hint = param.annotation
    if hint is param.empty:
        hint = type(default) if default is not None else None
    args = typing.get_args(hint)
    optional = type(None) in args
    if optional:
        rest = [a for a in args if a is not type(None)]
        hint = rest[0] if len(rest) == 1 else None
        args = typing.get_args(hint)
    length = None
    if hint in (int, float, str, bool):
        kind = hint.__name__
    elif typing.get_origin(hint) in (tuple, list) or hint in (tuple, list):
        kind = "floats"
        length = len(args) if args and Ellipsis not in args else (
            len(default) if default is not None else None)
    else:
        kind = "any"
    if allowed is not None:
        ok = (isinstance(allowed, tuple) and all(isinstance(a, str) for a in allowed)
              if kind == "str" else kind in ("int", "float") and _interval(allowed) is not None)
        if not ok:
            raise ValueError(f"{problem}: RANGES[{param.name!r}] = {allowed!r} does not fit a "
                             f"{kind}: give an interval such as '[1, inf)' for a number or a "
                             f"tuple of strings for a string")
    return Override(param.name, kind, default, optional, length, allowed)


def _interval(text):
    """``"(0, inf)"`` -> ``(0.0, inf, False, False)``: bounds and whether each is closed."""
    match = _INTERVAL.match(text) if isinstance(text, str) else None
    if not match:
        return None
    try:
        lo, hi = float(match[2]), float(match[3])
    except ValueError:
        return None
    return lo, hi, match[1] == "[", match[4] == "]"


def _check(spec: Override, value):
    """``value`` as ``spec``'s kind, inside its range; ValueError otherwise."""
    if value is None and spec.optional:
        return None
    value = _convert(spec, value)
    if isinstance(spec.allowed, tuple):
        if value not in spec.allowed:
            raise ValueError
    elif spec.allowed is not None:
        lo, hi, closed_lo, closed_hi = _interval(spec.allowed)
        if not ((lo <= value if closed_lo else lo < value)
                and (value <= hi if closed_hi else value < hi)):
            raise ValueError
    return value


def _convert(spec: Override, value):
    number = isinstance(value, numbers.Real) and not isinstance(value, (bool, np.bool_))
    if spec.kind == "int":
        if number and np.isfinite(value) and float(value).is_integer():
            return int(value)
    elif spec.kind == "float":
        if number and np.isfinite(float(value)):
            return float(value)
    elif spec.kind == "str":
        if isinstance(value, str):
            return value
        if isinstance(value, (int, np.integer)) and not isinstance(value, (bool, np.bool_)):
            return str(value)  # a name of digits typed as --set NAME=0 (an index, a group)
    elif spec.kind == "bool":
        if isinstance(value, (bool, np.bool_)):
            return bool(value)
        if isinstance(value, str) and value.lower() in ("true", "false"):
            return value.lower() == "true"
    elif spec.kind == "floats":
        if isinstance(value, (tuple, list, np.ndarray)) and (
                spec.length is None or len(value) == spec.length):
            number_spec = Override(spec.name, "float", None)
            return tuple(_convert(number_spec, v) for v in value)
    else:
        return value
    raise ValueError


def _name(module) -> str:
    return Path(module.__file__).stem


def _module(path: Path):
    spec = importlib.util.spec_from_file_location(f"casadi_keyframe_problem_{path.stem}", path)
    module = importlib.util.module_from_spec(spec)
    try:
        spec.loader.exec_module(module)
    except SyntaxError as err:
        where = f" (line {err.lineno})" if err.lineno else ""
        raise ValueError(f"problem file {path} is not valid Python: {err.msg}{where}") from None
    except Exception as err:  # noqa: BLE001 - the user's code: any error, reported by line
        raise ProblemFileError(path, "to import", err) from err
    return module


class ProblemFileError(ValueError):
    """A problem file that fails to import or whose ``build()`` raises: the message names
    the file, the line in that file the failure passed through and the exception; the
    library's own frames are left out (the exception's ``__cause__`` keeps them, which the
    command line prints with ``--debug``)."""

    def __init__(self, path, doing: str, err: BaseException):
        path = Path(path)
        where = _line_in(path, err.__traceback__)
        text = " ".join(str(err).split()) or "(no message)"
        super().__init__(f"problem file {path} failed {doing}{where}: "
                         f"{type(err).__name__}: {text}")
        self.path = path


def _line_in(path: Path, tb) -> str:
    """`` at line N (`code`)`` for the last frame of traceback ``tb`` in the file ``path``
    (the user's line nearest the failure), or a note that none is in it."""
    import linecache
    import traceback

    target = os.path.realpath(path)
    frames = [f for f in traceback.extract_tb(tb) if os.path.realpath(f.filename) == target]
    if not frames:
        return " (in code it calls, not in the file itself: --debug shows where)"
    frame = frames[-1]
    code = (frame.line or linecache.getline(frame.filename, frame.lineno)).strip()
    return f" at line {frame.lineno}" + (f" ({code})" if code else "")
