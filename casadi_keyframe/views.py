"""What a problem's pictures show beyond its model and keyframes: typed, immutable views.

A problem file passes one as ``ControlProblem(view=...)`` and the renderers in
:mod:`casadi_keyframe.render` read it: :class:`FlockView` for a flock seen from above,
:class:`ClothView` for a cloth in 3-D, :class:`BlendView` for fig. 6's blend drawn beside
its source clips.  Each keyframe term describes what it shows as a :class:`Marker`, which
renderers and exporters draw without knowing the term's class, with its
:class:`KeyframeGoal`: how the search's goal judges it, so that a picture says what the goal
says (:class:`Check`).  Plotting-free, so that a problem can hold one without importing
matplotlib.
"""
from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import MISSING, dataclass, field, fields
from typing import TYPE_CHECKING, TypeVar

import numpy as np

if TYPE_CHECKING:
    from .state import Trajectory




class Figure:
    """What outputs draw a marker as: a tag type that pictures and exporters key their
    writers by (a new kind of marker drawn as an existing figure changes no output)."""


class WholeShape(Figure):
    """A target for every particle, in particle order: drawn with the surface's faces (a
    wireframe) where the model has a surface, else as points."""


class Points(Figure):
    """Target points: some particles' targets, or a centre of mass."""


class Outline(Figure):
    """A region's closed outline in the plane z = 0."""


@dataclass(frozen=True)
class MarkerKind:
    """A kind of :class:`Marker`: its ``name``, the :class:`Figure` outputs draw it as (None:
    nothing to show in space) and whether its points are targets of particles' positions
    (``particles``: a picture colours each targeted particle by its distance)."""

    name: str
    figure: type[Figure] | None
    particles: bool = False


SHAPE = MarkerKind("shape", WholeShape, particles=True)
PARTICLES = MarkerKind("particles", Points, particles=True)
CENTER = MarkerKind("center", Points)
OUTLINE = MarkerKind("outline", Outline)
VELOCITY = MarkerKind("velocity", None)
MARKER_KINDS = {kind.name: kind for kind in (SHAPE, PARTICLES, CENTER, OUTLINE, VELOCITY)}

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


@dataclass(frozen=True)
class Marker:
    """What a keyframe term shows at its ``frame``, labelled ``label``.

    ``kind`` (a :class:`MarkerKind`, or its name) is :data:`SHAPE` (a target for every
    particle: ``points`` is ``(n, dim)`` in particle order, drawn with the surface's faces
    where the model has a surface), :data:`PARTICLES` (targets of some particles: ``points``
    ``(k, dim)`` for ``particles``), :data:`CENTER` (a centre-of-mass target: ``points``
    ``(1, dim)``), :data:`OUTLINE` (a region: its closed 2-D outline) or :data:`VELOCITY`
    (velocity targets of ``particles`` only: nothing to show in space, ``points`` empty).
    ``goal``, if given, is how the search's goal judges the term (:meth:`check`).
    """

    label: str
    frame: int
    kind: MarkerKind
    points: np.ndarray
    particles: np.ndarray | None = None
    goal: KeyframeGoal | None = None

    def __post_init__(self):
        kind = MARKER_KINDS.get(self.kind, self.kind) if isinstance(self.kind, str) else self.kind
        if not isinstance(kind, MarkerKind):
            raise ValueError(f"a marker's kind is one of {list(MARKER_KINDS)}, got {self.kind!r}")
        object.__setattr__(self, "kind", kind)
        points = np.array(np.atleast_2d(self.points), dtype=float)
        points.flags.writeable = False
        object.__setattr__(self, "points", points)
        object.__setattr__(self, "frame", int(self.frame))

    def targeted(self, x) -> np.ndarray | None:
        """The positions in ``x`` ``(n, dim)`` of the particles this marker's points target,
        in its points' order (None where they target no particle: a centre, a region)."""
        if not self.kind.particles:
            return None
        return x if self.particles is None else x[self.particles]

    def check(self, trajectory) -> Check | None:
        """How ``trajectory`` does against this keyframe (None without a ``goal``)."""
        return None if self.goal is None else self.goal.check(self.label, self.frame,
                                                               trajectory)

    @property
    def position_tolerance(self) -> float | None:
        """The tolerance on this keyframe's position miss (rms over its particles, or the
        centre's distance), in length units; None where none is checked."""
        tolerances = {} if self.goal is None else self.goal.tolerances
        found = [t for key in ("rms_position_error", "position_error")
                 if (t := tolerances.get(key)) is not None and np.isfinite(t)]
        return found[0] if found else None


@dataclass(frozen=True)
class View:
    """The base of every view; ``ControlProblem(view=...)`` takes only these (or None)."""


@dataclass(frozen=True)
class FlockView(View):
    """A flock seen from above; the agents in ``highlight`` are drawn larger, in orange
    (flock_race's runner)."""

    highlight: tuple[int, ...] = ()

    def __post_init__(self):
        object.__setattr__(self, "highlight", tuple(int(i) for i in self.highlight))


@dataclass(frozen=True)
class Ring:
    """A circle of ``radius`` about ``center`` in the plane orthogonal to ``normal``
    (cloth_toss's ring, which the cloth flies through)."""

    center: tuple[float, float, float]
    normal: tuple[float, float, float]
    radius: float

    def __post_init__(self):
        for name in ("center", "normal"):
            value = tuple(float(c) for c in np.ravel(getattr(self, name)))
            if len(value) != 3:
                raise ValueError(f"a ring's {name} is a 3-D point, got {value}")
            object.__setattr__(self, name, value)
        if not (np.isfinite(self.radius) and self.radius > 0):
            raise ValueError(f"a ring's radius must be positive, got {self.radius!r}")


@dataclass(frozen=True)
class ClothView(View):
    """A cloth in 3-D: ``camera`` is ``(elevation, azimuth)`` in degrees (matplotlib's
    ``view_init``), fixed for a whole animation; ``ring``, if any, is drawn as a thick circle."""

    camera: tuple[float, float] = (20.0, -60.0)
    ring: Ring | None = None

    def __post_init__(self):
        camera = tuple(float(a) for a in self.camera)
        if len(camera) != 2:
            raise ValueError(f"a camera is (elevation, azimuth) in degrees, got {self.camera}")
        object.__setattr__(self, "camera", camera)


@dataclass(frozen=True)
class Clip:
    """A source clip of fig. 6: a cape ``model`` and its passive ``trajectory``."""

    model: object = field(repr=False)
    trajectory: Trajectory = field(repr=False)


@dataclass(frozen=True, kw_only=True)
class BlendView(ClothView):
    """Fig. 6: a cape blended from the ``fall`` clip into the ``walk`` clip, drawn between them.

    The blend's frame k goes with the fall clip's time ``t_a + k dt`` and the walk clip's
    ``t_b + k dt``.  ``character`` is the animated body and ``animation`` the transition it
    moves through, on the fall clip's clock.
    """

    character: object
    animation: object = field(repr=False)
    t_a: float
    t_b: float
    fall: Clip
    walk: Clip

    def clip(self, kind: str) -> Clip:
        """The source clip ``kind``: "fall" or "walk"."""
        return self.fall if _kind(kind) == "fall" else self.walk

    def start(self, kind: str) -> float:
        """The time in source clip ``kind`` ("fall" or "walk") at the blend's frame 0."""
        return self.t_a if _kind(kind) == "fall" else self.t_b

    def clip_frame(self, kind: str, k: int, dt: float) -> int:
        """The frame of source clip ``kind`` that goes with blend frame ``k`` (time step
        ``dt``): ``start / dt + k``."""
        return int(round(self.start(kind) / dt)) + int(k)


def _kind(kind: str) -> str:
    if kind not in ("fall", "walk"):
        raise ValueError(f'a source clip is "fall" or "walk", got {kind!r}')
    return kind


def checked_view(view, scene=None) -> View | None:
    """``view`` if it is a :class:`View` or None, else a TypeError that says what to pass.

    ``scene`` is the keyword problems used before views were typed: any value is refused."""
    if scene is not None:
        raise TypeError("ControlProblem(scene=...) is now view=: pass a typed view from "
                        "casadi_keyframe.views, e.g. view=FlockView(highlight=[0]) or "
                        "view=ClothView(camera=(20, -60))")
    if view is not None and not isinstance(view, View):
        raise TypeError(f"a problem's view must be a casadi_keyframe.views.View (FlockView, "
                        f"ClothView, BlendView) or None, got {type(view).__name__}; e.g. "
                        f"{{'highlight': [0]}} becomes FlockView(highlight=[0]) and "
                        f"{{'view': (20, -60)}} ClothView(camera=(20, -60))")
    return view


V = TypeVar("V", bound=View)


def view_of(problem, kind: type[V]) -> V:
    """``problem.view`` if it is a ``kind``, a default ``kind()`` if the problem has none
    (and ``kind`` has defaults for every field), else a TypeError."""
    view = problem.view
    if isinstance(view, kind):
        return view
    if view is None and all(f.default is not MISSING or f.default_factory is not MISSING
                            for f in fields(kind)):
        return kind()
    raise TypeError(f"{problem.name}: this picture needs a {kind.__name__} (see "
                    f"casadi_keyframe.views), but the problem's view is "
                    f"{'None' if view is None else 'a ' + type(view).__name__}")
