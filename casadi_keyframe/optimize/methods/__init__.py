"""The search methods :func:`~.search.solve` can run, in one table, and the check of the
options a method is given.

A method is a runner (one search of one stage, see :class:`Method`) and the options it
takes; a new method is one new file and one entry in :data:`METHODS`, which ``solve``
dispatches through and the command line offers as ``--method``.
"""
from __future__ import annotations

import difflib
from collections.abc import Callable, Mapping
from dataclasses import dataclass

from . import gauss_newton, ipopt, lbfgsb, least_squares


@dataclass(frozen=True)
class Method:
    """One search method.

    * ``label``: its name in messages;
    * ``run(problem, evaluator, u0, maxiter, tol, options, on_iteration, deadline)``: one
      search from ``u0`` (in the evaluator's variables), calling ``on_iteration()`` after
      every iteration and stopping once ``deadline`` (the call's :class:`~.deadline.Deadline`)
      has passed;
      returns ``(status, message)`` (:mod:`.outcome`) or raises
      :class:`~casadi_keyframe.interrupts.Interrupted`;
    * ``option_names()``: the option names its library documents, read from the library;
    * ``unknown_options(options)``: the names among ``options`` it does not take (and a
      ValueError for a value its library refuses up front).
    """

    label: str
    run: Callable
    option_names: Callable[[], tuple]
    unknown_options: Callable[[dict], list]


def _undocumented(names: Callable[[], tuple]) -> Callable[[dict], list]:
    """``unknown_options`` for a library whose documented names are all it takes."""
    return lambda options: [key for key in options if key not in names()]


METHODS: dict[str, Method] = {
    "lbfgsb": Method("scipy's L-BFGS-B", lbfgsb.run, lbfgsb.option_names,
                     _undocumented(lbfgsb.option_names)),
    "ipopt": Method("IPOPT", ipopt.run, ipopt.option_names, ipopt.check_options),
    "gauss-newton": Method("the Gauss-Newton trust region", gauss_newton.run,
                           gauss_newton.option_names, gauss_newton.check_options),
    "least-squares": Method("scipy's least_squares", least_squares.run,
                            least_squares.option_names,
                            _undocumented(least_squares.option_names)),
}


def get_method(name) -> Method:
    """The :data:`METHODS` entry ``name`` (ValueError naming the choices otherwise)."""
    if not isinstance(name, str) or name not in METHODS:
        raise ValueError(f"unknown method {name!r}; choose one of {', '.join(METHODS)}")
    return METHODS[name]


def check_options(name: str, options) -> dict:
    """``options`` for the method ``name`` as a new dict, refused before the search if a key
    is not one of the method's options (scipy's ``_check_unknown_options`` only warns):
    ValueError naming the key, the closest valid names and the valid ones (or, for a long
    list, where to read it)."""
    method = get_method(name)
    if options is None:
        return {}
    if not isinstance(options, Mapping):
        raise TypeError(f"options must be a dict of {method.label} options, got "
                        f"{type(options).__name__}")
    options = dict(options)
    named = [key for key in options if not isinstance(key, str)]
    if named:
        raise TypeError(f"options keys are {method.label} option names (strings), got "
                        f"{named!r}")
    unknown = method.unknown_options(options)
    if not unknown:
        return options
    names = method.option_names()
    hints = []
    for key in unknown:
        close = difflib.get_close_matches(key, names, n=3)
        hints.append(f"{key!r}" + (f" (did you mean {_either(close)}?)" if close else ""))
    valid = (f"{method.label} takes {', '.join(names)}" if len(names) <= 30 else
             f"{method.label} documents {len(names)} options, listed by "
             f"{method.option_names.__module__}.option_names()")
    raise ValueError(f"options for method {name!r}: unknown option"
                     f"{'s' if len(unknown) > 1 else ''} {', '.join(hints)}; {valid}")


def _either(names) -> str:
    quoted = [repr(n) for n in names]
    return quoted[0] if len(quoted) == 1 else f"{', '.join(quoted[:-1])} or {quoted[-1]}"
