"""What a keyframe term shows (:class:`Marker`), so that pictures and exporters draw it
without knowing the term's class: its kind (:class:`MarkerKind`: a whole shape, some
particles, a centre of mass, a region's outline, velocities only) and the :class:`Figure`
that kind is drawn as, which outputs key their writers by, and how the goal judges it
(:mod:`.keyframe_goal`).  Plotting-free.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .keyframe_goal import Check, KeyframeGoal


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
