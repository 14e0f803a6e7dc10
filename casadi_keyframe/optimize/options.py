"""Typed options, read once from their loose forms: :class:`TypedOptions`, a frozen dataclass
whose fields are the names a part of a solve takes (a method's own options, multiple
shooting's, the finish's, the rounds'), with their defaults, the checks of their values and
one reader of a dict, a shorthand or the options themselves (:meth:`TypedOptions.read`)."""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, fields
from typing import ClassVar

import numpy as np


@dataclass(frozen=True)
class TypedOptions:
    """A method's own options as a frozen dataclass: its fields are the names, with their
    defaults; ``CHECKS`` maps a name to ``(what it takes, test)``; ``label`` names the
    method in messages."""

    label: ClassVar[str] = "the method"
    CHECKS: ClassVar[dict] = {}

    @classmethod
    def names(cls) -> tuple[str, ...]:
        return tuple(f.name for f in fields(cls))

    @classmethod
    def unknown(cls, options: Mapping) -> list[str]:
        """The names among ``options`` it does not take; a ValueError for a value out of
        its range, naming the option and what it takes."""
        for key, value in options.items():
            if key in cls.CHECKS and not cls.CHECKS[key][1](value):
                raise ValueError(f"{cls.label} option {key!r} must be {cls.CHECKS[key][0]}, "
                                 f"got {value!r}")
        return [key for key in options if key not in cls.names()]

    @classmethod
    def make(cls, options: Mapping) -> "TypedOptions":
        return cls(**options)

    @classmethod
    def read(cls, value, what: str, *, single=None, takes: str = ""):
        """``value`` as these options: None, the options themselves, a dict of their fields
        (an unknown name refused, naming ``what`` and the names it takes) or a value of the
        type ``single`` (their first field alone); anything else refused (``takes`` says
        what is taken)."""
        if value is None or isinstance(value, cls):
            return value
        if isinstance(value, Mapping):
            unknown = sorted(set(value) - set(cls.names()))
            if unknown:
                raise ValueError(f"{what}: unknown option(s) {unknown}; it takes "
                                 f"{', '.join(cls.names())}")
            return cls(**value)
        if single is not None and isinstance(value, single) and not isinstance(value, bool):
            return cls(value)
        raise ValueError(f"{what} must be {takes}, got {value!r}")

    def as_dict(self) -> dict:
        return {name: getattr(self, name) for name in self.names()}


def real(value) -> bool:
    """A finite real number (not a bool)."""
    return (isinstance(value, (int, float, np.integer, np.floating))
            and not isinstance(value, bool) and bool(np.isfinite(value)))


def whole(value) -> bool:
    """A whole number (not a bool)."""
    return isinstance(value, (int, np.integer)) and not isinstance(value, bool)
