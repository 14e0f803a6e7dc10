"""What a search method is, written once: :class:`Method` (the contract every
:data:`~.METHODS` entry keeps), :class:`SearchCall` (what one run of it is given), and the
two kinds of typed options a method takes: :class:`LibraryOptions` (a library's own names,
passed through) and :class:`~..options.TypedOptions` (a method's own fields, with
their defaults and checks)."""
from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import ClassVar

from ..options import TypedOptions

__all__ = ["LibraryOptions", "Method", "SearchCall", "TypedOptions"]


@dataclass(frozen=True)
class SearchCall:
    """What one run of a method is given beside the problem, the evaluator and the start:

    * ``maxiter``, ``tol``: the stage's iteration limit and the method's tolerance;
    * ``options``: the method's own options, typed (its :attr:`Method.options` type made
      them from the solve's settings);
    * ``deadline``: the call's one :class:`~..deadline.Deadline`, to ask between steps;
    * ``on_iteration()``: to call after every iteration (it records the history, writes the
      checkpoint, raises on a signal or, with ``stop="goal"``, when the goal is met).
    """

    maxiter: int
    tol: float
    options: object
    deadline: object
    on_iteration: Callable[[], None]


@dataclass(frozen=True)
class Method:
    """One search method: an entry of :data:`~.METHODS`.

    * ``label``: its name in messages;
    * ``run(problem, evaluator, u0, call) -> (status, message)``: one search of one stage
      from ``u0`` (in the evaluator's variables), ``call`` a :class:`SearchCall`.  It asks
      ``evaluator(x) -> (f, gradient)`` where it needs a gradient, and
      ``evaluator.offer(x)`` (value and run, no gradient: judged and ranked with every other
      point, the best kept) where it does not; it calls ``call.on_iteration()`` after every
      iteration, stops once ``call.deadline.passed()`` (a library with a wall-time budget
      of its own gets ``call.deadline.left()``) and lets a pending signal stop it between
      steps (:func:`~casadi_keyframe.interrupts.check`; the evaluator checks at every
      evaluation).  It returns ``(status, message)`` (:mod:`..outcome`) or raises
      :class:`~casadi_keyframe.interrupts.Interrupted`; the best point is the evaluator's.
    * ``options``: the type of its options (:class:`LibraryOptions` or
      :class:`TypedOptions`): ``names()``, ``unknown(mapping)`` (the names it does not take;
      ValueError for a value it refuses) and ``make(mapping)``, the typed options; the
      solve's settings hold them, and the command line reaches every name with
      ``--option KEY=VALUE``.

    A new method (the transcription of issue 40) is its own folder or file with its
    ``run`` and options type, and one entry in :data:`~.METHODS`.
    """

    label: str
    run: Callable
    options: type
    stop: str | None = None
    """The stop rule where the settings leave it open (None: the solve's default, the goal
    where keyframes declare tolerances); a method whose point is what follows the goal
    (least effort under it) says "method"."""
    ranks: str = "objective"
    """How the points that meet the goal are ranked: by the objective, or ("effort") by
    their control cost, for a method that minimises the effort under the goal."""
    shoots: bool = True
    """Whether it can search multiple shooting's segments (their controls and nodes); a
    method that poses the whole motion its own way (the transcription: every step met
    step by step) does not, and a problem file's multiple shooting is left out for it."""
    finishes: bool = True
    """Whether a problem file's finish (the effort lowered with the keyframes held) follows
    it; a method that already minimises the effort under the goal (the transcription) ends
    where that finish would, so the file's is left out for it (one asked for in the solve
    request still runs)."""


class LibraryOptions:
    """Options passed through to the library a method runs (scipy, IPOPT), by the names the
    library documents (:meth:`names`, read from it); frozen, in the order given.  A subclass
    gives ``names`` and may ask the library itself in ``unknown``."""

    label: ClassVar[str] = "the library"

    def __init__(self, items: Mapping | None = None):
        self._items = tuple((items or {}).items())

    @classmethod
    def names(cls) -> tuple[str, ...]:
        raise NotImplementedError

    @classmethod
    def unknown(cls, options: Mapping) -> list[str]:
        """The names among ``options`` the library does not document."""
        known = cls.names()
        return [key for key in options if key not in known]

    @classmethod
    def make(cls, options: Mapping) -> "LibraryOptions":
        return cls(options)

    def as_dict(self) -> dict:
        return dict(self._items)

    def __eq__(self, other) -> bool:
        return type(other) is type(self) and other._items == self._items

    def __hash__(self) -> int:
        return hash((type(self), tuple(k for k, _ in self._items)))

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.as_dict()!r})"
