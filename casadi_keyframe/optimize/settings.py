"""One solve request, typed: :class:`SolveSettings`, built once (from a problem file's
``SOLVE``, the command line or a sweep point: :func:`settings_from`; from ``solve``'s
keywords: :func:`as_settings`) and passed whole to :func:`~.search.solve`.

Every default of a solve is written here, once: the dataclass's fields.  Every string form
of a setting (``--finish effort,window=20``, ``--shooting init=blend,workers=2``, ``--option
radius=0.5``) is read here too, by one reader of ``KEY=VALUE`` items (:func:`read_items`).
"""
from __future__ import annotations

import ast
import math
import numbers
from collections.abc import Mapping
from dataclasses import dataclass, fields, replace
from fractions import Fraction

from ..adjoints import get_gradient
from .finish import Finish, finish_options
from .goal import STOPS
from .methods import check_options, get_method
from .rounds import Rounds, rounds_options
from .shooting import ShootingOptions, shooting_options


@dataclass(frozen=True)
class SolveSettings:
    """How to solve: the method and its options, the gradient route, the limits, the stages,
    multiple shooting, rounds, the finish and the stop rule.  Each field in full:
    ``docs/explanations/solving.md``."""

    method: str = "lbfgsb"
    """A :data:`~.methods.METHODS` name."""
    options: object = None
    """The method's typed options (a mapping is read and checked against the names the
    method documents; None: its defaults)."""
    gradient: object = None
    """The gradient route (a name or a route; None: the registry's default)."""
    maxiter: int = 200
    """Iterations per stage (and per round)."""
    tol: float = 1e-8
    """The method's convergence tolerance."""
    time_limit: float | None = None
    """Seconds of wall clock over the whole call (None: no limit)."""
    stop: str | None = None
    """``"goal"`` (stop once every keyframe is within its tolerance), ``"method"`` (at the
    method's own test), None (the goal where the problem declares tolerances)."""
    continuation: tuple | None = None
    """Coarser time steps solved first, coarse to fine (s)."""
    resolutions: tuple | None = None
    """Coarser meshes solved first (problems or build overrides), coarse to fine."""
    coarser_only: bool = False
    """Keep only the ``resolutions`` coarser than the problem solved (a problem file's
    defaults: a problem built that coarse itself has none)."""
    homotopy: tuple | None = None
    """Levels of the model solved first (problems or build overrides)."""
    shooting: ShootingOptions | None = None
    """Multiple shooting (a number of segments, a dict of its options; None or 1: none)."""
    rounds: Rounds | None = None
    """Augmented-Lagrangian rounds holding the keyframes hard (a number, a dict)."""
    finish: Finish | None = None
    """A last stage with the keyframes held (``"land"``, ``"effort"``, with options)."""

    def __post_init__(self):
        get_method(self.method)
        sets = {"options": check_options(self.method, self.options),
                "gradient": get_gradient(self.gradient),
                "continuation": _sequence("continuation", self.continuation, times=True),
                "resolutions": _sequence("resolutions", self.resolutions),
                "homotopy": _sequence("homotopy", self.homotopy),
                "shooting": _shooting(self.shooting),
                "rounds": rounds_options(self.rounds),
                "finish": finish_options(read_kind(self.finish, "finish",
                                                   "KIND,window=N,maxiter=N"))}
        for name, value in sets.items():
            object.__setattr__(self, name, value)
        _check_limits(self.maxiter, self.tol, self.time_limit)
        if self.stop is not None and self.stop not in STOPS:
            raise ValueError(f"stop must be 'goal' (stop once every keyframe is within its "
                             f"tolerance) or 'method' (run the method to its own test), got "
                             f"{self.stop!r}")
        if self.rounds is not None and self.finish is not None:
            raise ValueError("the finish holds the keyframes after one search; augmented-"
                             "Lagrangian rounds (--rounds, --weight-growth, or the file's) "
                             "hold them their own way: choose one (--finish none)")
        if self.shooting is not None and not get_method(self.method).shoots:
            raise ValueError(f"multiple shooting (--segments, --shooting) searches segments' "
                             f"controls and nodes, which {get_method(self.method).label} does "
                             "not: it poses every step itself; drop --segments, or choose "
                             "another --method")
        if self.rounds is not None and self.resolutions and not self.coarser_only:
            raise ValueError("coarse meshes (--resolution) and augmented-Lagrangian rounds "
                             "(--rounds, --weight-growth) do not combine: choose one")

    def describe(self) -> str:
        """``"method lbfgsb, maxiter 200, gradient adjoint, finish effort"``: the method, its
        limit and route, then every setting that is not its default."""
        plain = SolveSettings()
        said = [f"method {self.method}", f"maxiter {self.maxiter}",
                f"gradient {self.gradient.name}"]
        given = given_options(self.options)
        if given:
            said.append("options " + ",".join(f"{k}={v}" for k, v in given.items()))
        for field in fields(self):
            value = getattr(self, field.name)
            if field.name not in ("method", "options", "maxiter", "gradient") and (
                    value != getattr(plain, field.name)):
                said.append(f"{field.name} {_said(value)}")
        return ", ".join(said)


REQUEST = tuple(f.name for f in fields(SolveSettings)) + ("weight_growth",)
"""The names a request takes: the settings' fields, and ``weight_growth`` (the rounds')."""


def as_settings(settings=None, **keywords) -> SolveSettings:
    """``settings`` (a :class:`SolveSettings`, a method's name, or None) with ``keywords``
    (any of :data:`REQUEST`, in the loose forms the fields take) over it: what ``solve``'s
    keyword form builds."""
    if isinstance(settings, str):
        settings, keywords = None, {"method": settings, **keywords}
    if settings is not None and not isinstance(settings, SolveSettings):
        raise TypeError(f"settings must be a SolveSettings or a method's name, got "
                        f"{type(settings).__name__}")
    unknown = sorted(set(keywords) - set(REQUEST))
    if unknown:
        raise TypeError(f"unknown solve setting(s) {', '.join(unknown)}; a solve takes "
                        f"{', '.join(REQUEST)}")
    base = settings or SolveSettings()
    if "weight_growth" in keywords:
        rounds = keywords.pop("weight_growth")
        held = keywords.get("rounds", base.rounds)
        keywords["rounds"] = {**_rounds_dict(held), "weight_growth": rounds}
    if "method" in keywords and "options" not in keywords:
        keywords["options"] = None  # the new method's own defaults
    return replace(base, **keywords) if keywords else base


def settings_from(file: Mapping | None = None, given: Mapping | None = None) -> SolveSettings:
    """The settings of a solve a problem file's ``SOLVE`` (``file``) and the command line or
    a sweep point (``given``: the values asked for; None is not asked) ask for: what is
    given wins, then the file's, then the defaults; the file's method options hold for its
    own method only; multiple shooting's options go over the file's (``segments`` 1 or less:
    none; the file's left out for a method that does not shoot,
    :attr:`~.methods.Method.shoots`); rounds asked for replace the file's default meshes,
    and meshes asked for its rounds (both asked: refused); ``finish`` ``"none"`` drops the
    file's, which is left out too for a method that minimises the effort under the goal
    itself (:attr:`~.methods.Method.finishes`)."""
    file = dict(file or {})
    given = {k: v for k, v in (given or {}).items() if v is not None}
    for where, values in (("the problem file's SOLVE", file), ("a solve request", given)):
        unknown = sorted(set(values) - set(REQUEST))
        if unknown:
            raise TypeError(f"{where}: unknown setting(s) {', '.join(unknown)}; a solve "
                            f"takes {', '.join(REQUEST)}")
    values = {**{k: file[k] for k in ("gradient", "maxiter", "tol", "time_limit", "stop",
                                      "continuation", "homotopy", "method") if k in file},
              **{k: given[k] for k in ("gradient", "maxiter", "tol", "time_limit", "stop",
                                       "continuation", "homotopy", "method") if k in given}}
    own = file.get("method", SolveSettings.method) == values.get("method",
                                                                 SolveSettings.method)
    values["options"] = {**(file.get("options") or {} if own else {}),
                         **(given.get("options") or {})}
    asked = {k: given[k] for k in ("rounds", "weight_growth") if k in given}
    if asked and given.get("resolutions"):
        raise ValueError("coarse meshes (--resolution) and augmented-Lagrangian rounds "
                         "(--rounds, --weight-growth) do not combine: choose one")
    rounds = asked or ({} if given.get("resolutions") else
                       {k: file[k] for k in ("rounds", "weight_growth") if k in file})
    values["rounds"] = rounds or None
    if "resolutions" in given:
        values["resolutions"] = given["resolutions"]
    elif not rounds and file.get("resolutions"):
        values["resolutions"], values["coarser_only"] = file["resolutions"], True
    method = get_method(values.get("method", SolveSettings.method))
    values["shooting"] = _merged_shooting(file.get("shooting") if method.shoots else None,
                                          given.get("shooting"))
    finish = given.get("finish", file.get("finish") if method.finishes else None)
    if isinstance(finish, str) and finish != "none" and split_top(finish)[:1] == ["none"]:
        raise ValueError(f"--finish none drops the finish and takes no options; got "
                         f"{finish!r}: give 'none' alone, or a kind with options such as "
                         "effort,window=20")
    values["finish"] = None if finish == "none" else finish
    return SolveSettings(**values)


def _merged_shooting(file, given) -> dict | None:
    """Multiple shooting's options asked for over the file's; None where it has no segments
    (ValueError for options asked for a run without them)."""
    asked = {"segments": given} if isinstance(given, int) else dict(given or {})
    base = {"segments": file} if isinstance(file, int) else dict(file or {})
    merged = {**base, **asked}
    if merged and merged.get("segments", 1) <= 1:
        others = sorted(set(asked) - {"segments"})
        if others:
            why = "" if "segments" in asked else "; the problem asks for none"
            raise ValueError(f"--shooting {', '.join(others)} (or --scheduler) set multiple "
                             f"shooting's options, but this run has none: give --segments K "
                             f"(K >= 2){why}")
        return None
    return merged or None


def _shooting(value) -> ShootingOptions | None:
    """Multiple shooting's options read (:func:`~.shooting.shooting_options`, a string of
    ``KEY=VALUE`` items too); one segment or fewer is none."""
    opts = shooting_options(read_items(value, "--shooting", "init=blend,workers=2")
                            if isinstance(value, str) else value)
    return None if opts is None or opts.segments <= 1 else opts


def _rounds_dict(value) -> dict:
    if value is None:
        return {}
    if isinstance(value, Rounds):
        return {f.name: getattr(value, f.name) for f in fields(Rounds)}
    return dict(value) if isinstance(value, Mapping) else {"rounds": value}


def _sequence(name: str, value, times: bool = False):
    """``value`` (None or a list of levels) as a tuple, refused by ``name`` if it is a single
    level (a dict, a string) or, with ``times``, is not a list of numbers."""
    if value is None:
        return None
    if isinstance(value, (dict, str)) or not hasattr(value, "__iter__"):
        raise ValueError(f"{name} must be a list, first to last, got {value!r}")
    out = tuple(value)
    if times and not all(isinstance(v, numbers.Real) and not isinstance(v, bool)
                         for v in out):
        raise ValueError(f"{name} must be a list of time steps in seconds, coarse to fine, "
                         f"got {value!r}")
    return out


def _check_limits(maxiter, tol, time_limit) -> None:
    """Refuse a limit before any simulation runs (ValueError naming it and what it takes)."""
    if isinstance(maxiter, bool) or not isinstance(maxiter, numbers.Integral) or maxiter < 1:
        raise ValueError(f"maxiter must be a whole number >= 1 (iterations per stage), got "
                         f"{maxiter!r}")
    if not _positive(tol):
        raise ValueError(f"tol must be a finite number > 0 (the method's convergence "
                         f"tolerance), got {tol!r}")
    if time_limit is not None and not _positive(time_limit):
        raise ValueError(f"time_limit must be a finite positive number of seconds (None for "
                         f"no limit), got {time_limit!r}")


def _positive(value) -> bool:
    return (isinstance(value, numbers.Real) and not isinstance(value, bool)
            and math.isfinite(value) and value > 0)


def given_options(options) -> dict:
    """The items of a method's typed options that are not its defaults."""
    plain = type(options).make({}).as_dict()
    return {k: v for k, v in options.as_dict().items() if k not in plain or plain[k] != v}


def _said(value) -> str:
    """A setting as ``describe`` says it: a typed one by its first field and the others it
    sets."""
    if hasattr(value, "__dataclass_fields__"):
        first, *rest = fields(value)
        said = [str(getattr(value, first.name))] + [
            f"{f.name}={getattr(value, f.name)}" for f in rest
            if getattr(value, f.name) != f.default]
        return ",".join(said)
    if hasattr(value, "as_dict"):
        return ",".join(f"{k}={v}" for k, v in value.as_dict().items())
    return str(list(value) if isinstance(value, tuple) else value)


# -- the string forms ------------------------------------------------------------------------
def read_kind(text, what: str, form: str):
    """``"effort,window=20"`` -> ``{"kind": "effort", "window": 20}`` (the first item a
    kind, the others :func:`read_items`'); anything but a string as it is."""
    if not isinstance(text, str):
        return text
    kind, *items = split_top(text) or [""]
    if "=" in kind:
        raise ValueError(f"{what}: expected {form}, got {text!r}")
    return {"kind": kind.strip(), **_items(items, what, form)}


def read_items(text, what: str, example: str) -> dict:
    """``"init=blend,workers=2"`` -> ``{"init": "blend", "workers": 2}``: ``KEY=VALUE`` items
    (values as :func:`parse_value` reads them), ``what`` and ``example`` naming the option
    in a refusal; anything but a string as it is."""
    if not isinstance(text, str):
        return text
    return _items(split_top(text), what, f"KEY=VALUE,... such as {example}")


def _items(items, what: str, form: str) -> dict:
    out = {}
    for item in items:
        key, sep, value = item.partition("=")
        if not sep or not key.strip().isidentifier():
            raise ValueError(f"{what}: expected {form}, got the item {item!r}")
        out[once(out, key.strip(), what)] = parse_value(value)
    return out


def once(given: Mapping, key: str, what: str) -> str:
    """``key``, refused (ValueError naming ``what``) if ``given`` has it already: a key
    typed twice is a mistake whichever value was meant, never the last one silently."""
    if key in given:
        raise ValueError(f"{what}: {key} is given twice (first {given[key]!r}): give it once")
    return key


def key_value(item: str, option: str, example: str) -> tuple[str, str]:
    """``"agents=50"`` -> ``("agents", "50")``; ValueError naming ``option`` otherwise."""
    key, sep, value = item.partition("=")
    key = key.strip()
    if not sep or not key.isidentifier():
        raise ValueError(f"{option} expects KEY=VALUE such as {example}, got {item!r}")
    return key, value


def parse_value(text: str):
    """A value typed as text: a Python literal, else a fraction as a float, else the text."""
    try:
        return ast.literal_eval(text.strip())
    except (ValueError, SyntaxError, MemoryError, RecursionError):
        try:
            return float(Fraction(text.strip()))
        except (ValueError, ZeroDivisionError):
            return text


def split_top(text: str) -> list[str]:
    """``"1,(2,3),'a,b'"`` -> ``["1", "(2,3)", "'a,b'"]``; empty items dropped."""
    parts, depth, quote, current = [], 0, None, ""
    for char in text:
        if quote:
            quote = None if char == quote else quote
        elif char in "'\"":
            quote = char
        elif char in "([{":
            depth += 1
        elif char in ")]}":
            depth -= 1
        elif char == "," and depth == 0:
            parts.append(current)
            current = ""
            continue
        current += char
    return [p.strip() for p in parts + [current] if p.strip()]
