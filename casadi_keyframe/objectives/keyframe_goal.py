"""How the search's goal judges one keyframe term, in words that pictures and reports share:
what each entry of a term's miss measures (:data:`MEASURES`), one measure's :class:`Miss`, a
trajectory's :class:`Check` against the keyframe, and the term's :class:`KeyframeGoal` (its
tolerances and its own test, which the goal calls; a picture never tests a tolerance
itself, it says what the goal says).  Plotting-free.
"""
from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field

# What each entry of a term's miss (StateTerm.miss) measures: (name, quantity, bound); a
# "length" in the model's length unit, a "speed" in that per second, a "fraction" of agents.
# A bound "most" is met at or below its tolerance, "least" at or above it.
MEASURES = {"rms_position_error": ("rms miss", "length", "most"),
            "max_position_error": ("max", "length", "most"),
            "rms_velocity_error": ("velocity rms miss", "speed", "most"),
            "position_error": ("centre-of-mass miss", "length", "most"),
            "velocity_error": ("velocity miss", "speed", "most"),
            "fraction_inside": ("inside", "fraction", "least")}


@dataclass(frozen=True)
class Miss:
    """One measure of a keyframe's miss (``key`` of :data:`MEASURES`, named ``name``) in a
    trajectory: its ``value`` and the ``tolerance`` it is held to (None: not checked)."""

    key: str
    name: str
    quantity: str
    bound: str
    value: float
    tolerance: float | None


@dataclass(frozen=True)
class Check:
    """How a trajectory does against one keyframe (``label`` at ``frame``): its ``misses``
    and ``met``, the goal's verdict on it (None: the keyframe declares no tolerance)."""

    label: str
    frame: int
    misses: tuple
    met: bool | None

    @property
    def verdict(self) -> str:
        """``"HIT"``, ``"MISSED"`` or ``"no tolerance"``."""
        return "no tolerance" if self.met is None else ("HIT" if self.met else "MISSED")


@dataclass(frozen=True)
class KeyframeGoal:
    """How the search's goal judges a keyframe term: its ``tolerances`` (a key of
    :data:`MEASURES` -> tolerance, None or inf: not checked), whether the goal counts it
    (``judged``: the term declares a tolerance), and the term's own ``miss`` and
    ``shortfall`` (a phrase, or None when every tolerance holds), which the goal calls
    (:func:`casadi_keyframe.optimize.goal.verdict`): a picture never tests a tolerance
    itself."""

    tolerances: Mapping
    judged: bool
    miss: Callable = field(repr=False, compare=False)
    shortfall: Callable = field(repr=False, compare=False)

    def __post_init__(self):
        unknown = set(self.tolerances) - set(MEASURES)
        if unknown:
            raise ValueError(f"a keyframe goal's tolerances are keyed by {list(MEASURES)}, "
                             f"got {sorted(unknown)}")
        object.__setattr__(self, "tolerances", {k: None if v is None else float(v)
                                                for k, v in self.tolerances.items()})

    def check(self, label: str, frame: int, trajectory) -> Check:
        """The :class:`Check` of ``trajectory``: the term's misses beside their tolerances,
        met when the goal's test (the term's ``shortfall``) finds nothing short."""
        miss = self.miss(trajectory)
        misses = tuple(Miss(key, *MEASURES[key], float(miss[key]), self.tolerances.get(key))
                       for key in MEASURES if key in miss)
        met = (self.shortfall(trajectory) is None) if self.judged else None
        return Check(label, int(frame), misses, met)
