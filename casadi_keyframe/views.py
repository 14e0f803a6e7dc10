"""What a problem's pictures show beyond its model and keyframes: typed, immutable views.

A problem file passes one as ``ControlProblem(view=...)`` and the renderers in
:mod:`casadi_keyframe.render` read it: :class:`FlockView` for a flock seen from above,
:class:`ClothView` for a cloth in 3-D, :class:`BlendView` for fig. 6's blend drawn beside
its source clips.  What each keyframe term shows, and how the goal judges it, is the term's
(:mod:`casadi_keyframe.objectives.markers`).  Plotting-free, so that a problem can hold one
without importing matplotlib.
"""
from __future__ import annotations

from dataclasses import MISSING, dataclass, field, fields
from typing import TYPE_CHECKING, TypeVar

import numpy as np

if TYPE_CHECKING:
    from .state import Trajectory


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
