"""The search methods :func:`~..search.solve` can run, in one table, and the check of the
options a method is given.

A method is a runner (one search of one stage) and the type of the options it takes
(:class:`~.base.Method`, the contract); a new method is one new file (or folder) and one
entry in :data:`METHODS`, which ``solve`` dispatches through and the command line offers as
``--method`` (its options as ``--option KEY=VALUE``).
"""
from __future__ import annotations

import difflib
from collections.abc import Mapping

from ..positions import method as transcription
from . import gauss_newton, ipopt, lbfgsb, least_squares
from .base import LibraryOptions, Method, SearchCall, TypedOptions

METHODS: dict[str, Method] = {
    "lbfgsb": Method("scipy's L-BFGS-B", lbfgsb.run, lbfgsb.LbfgsbOptions),
    "ipopt": Method("IPOPT", ipopt.run, ipopt.IpoptOptions),
    "gauss-newton": Method("the Gauss-Newton trust region", gauss_newton.run,
                           gauss_newton.GaussNewtonOptions),
    "least-squares": Method("scipy's least_squares", least_squares.run,
                            least_squares.LeastSquaresOptions),
    "transcription": Method("the transcription in positions", transcription.run,
                            transcription.TranscriptionOptions, stop="method",
                            ranks="effort", shoots=False, finishes=False),
}

__all__ = ["METHODS", "LibraryOptions", "Method", "SearchCall", "TypedOptions",
           "check_options", "get_method"]


def get_method(name) -> Method:
    """The :data:`METHODS` entry ``name`` (ValueError naming the choices otherwise)."""
    if not isinstance(name, str) or name not in METHODS:
        raise ValueError(f"unknown method {name!r}; choose one of {', '.join(METHODS)}")
    return METHODS[name]


def check_options(name: str, options):
    """``options`` (None, a mapping, or the method's typed options) as the method ``name``'s
    typed options, refused before the search if a key is not one of the method's options
    (scipy's ``_check_unknown_options`` only warns): ValueError naming the key, the closest
    valid names and the valid ones (or, for a long list, where to read it)."""
    method = get_method(name)
    if isinstance(options, method.options):
        return options
    if options is None:
        return method.options.make({})
    if not isinstance(options, Mapping):
        raise TypeError(f"options must be a dict of {method.label} options, got "
                        f"{type(options).__name__}")
    options = dict(options)
    named = [key for key in options if not isinstance(key, str)]
    if named:
        raise TypeError(f"options keys are {method.label} option names (strings), got "
                        f"{named!r}")
    unknown = method.options.unknown(options)
    if not unknown:
        return method.options.make(options)
    names = method.options.names()
    hints = []
    for key in unknown:
        close = difflib.get_close_matches(key, names, n=3)
        hints.append(f"{key!r}" + (f" (did you mean {_either(close)}?)" if close else ""))
    valid = (f"{method.label} takes {', '.join(names)}" if len(names) <= 30 else
             f"{method.label} documents {len(names)} options, listed by "
             f"{method.options.__module__}.option_names()")
    raise ValueError(f"options for method {name!r}: unknown option"
                     f"{'s' if len(unknown) > 1 else ''} {', '.join(hints)}; {valid}")


def _either(names) -> str:
    quoted = [repr(n) for n in names]
    return quoted[0] if len(quoted) == 1 else f"{', '.join(quoted[:-1])} or {quoted[-1]}"
