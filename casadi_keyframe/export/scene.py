"""What a result shows, as plain arrays every exporter writes: the particles at each frame,
the surface's triangles, the colliders at each frame, the keyframe targets, the view's ring,
a blend's source clips, the keyframe misses and a cloth's largest stretch per frame.

Positions are always 3-D (a 2-D flock lies in the plane z = 0, seen from above), in metres,
z up, as the problems build them.  Nothing here knows a file format.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..geometry import moves
from ..models.base import PhysicalReport, Surface
from ..optimize.report import format_misses
from ..objectives.markers import Points, WholeShape
from ..views import BlendView, ClothView, FlockView


def points3(x) -> np.ndarray:
    """``(..., 3)`` positions: 2-D ones get z = 0."""
    x = np.asarray(x, dtype=float)
    if x.shape[-1] == 3:
        return x
    return np.concatenate([x, np.zeros(x.shape[:-1] + (3 - x.shape[-1],))], axis=-1)


@dataclass
class Body:
    """A collider: its typed ``shapes`` per frame (:class:`~casadi_keyframe.geometry.BodyShape`:
    a plane's patch, a round body, a triangle mesh); ``moving`` says whether it changes over
    the frames."""

    name: str
    shapes: list
    moving: bool

    @property
    def shape(self):
        """The shape at the first frame (a still body's, at every frame)."""
        return self.shapes[0]

    def at(self, n: int):
        """The shape at frame ``n``."""
        return self.shapes[n if self.moving else 0]

    def frames(self) -> list:
        """The shapes an output writes: every frame's if the body moves, else the first."""
        return self.shapes if self.moving else self.shapes[:1]


def bodies(model, times, prefix: str = "") -> list[Body]:
    """The colliders of ``model`` at each of ``times``."""
    out = []
    for i, body in enumerate(model.colliders):
        shapes = [body.shape(t) for t in times]
        out.append(Body(f"{prefix}{type(body).__name__}{i}", shapes, moves(shapes)))
    return out


@dataclass
class Target:
    """A keyframe's target at ``frame``: its ``figure`` (:class:`~..objectives.markers.Figure`:
    ``WholeShape``, ``points`` for every particle, drawn with the surface's faces;
    ``Points``, some particles or a centre of mass; ``Outline``, a region's closed outline
    in z = 0), which each exporter keys its writer by; ``label`` the term's."""

    label: str
    frame: int
    figure: type
    points: np.ndarray


def targets(problem) -> list[Target]:
    """The targets of the problem's keyframe terms that have a figure to show (their
    markers; a whole-body target is drawn as points where the model has no surface)."""
    surface = isinstance(problem.model, Surface)
    out = []
    for m in problem.objective_terms.markers():
        figure = m.kind.figure
        if figure is WholeShape and not surface:
            figure = Points
        if figure is not None:
            out.append(Target(m.label, m.frame, figure, points3(m.points)))
    return out


@dataclass
class Clip:
    """A blend's source clip over the blend's frames: ``positions`` ``(steps + 1, n, 3)``,
    its colliders (the character on the clip's clock) and the clip's ``times``."""

    name: str
    positions: np.ndarray
    bodies: list
    times: np.ndarray


@dataclass
class Scene:
    """Everything an export writes for one result (see the module docstring)."""

    name: str
    dt: float
    positions: np.ndarray            # (frames, n, 3)
    faces: np.ndarray | None         # (m, 3) triangles of a cloth, None for a flock
    bodies: list
    targets: list
    dim: int = 3
    highlight: tuple = ()
    ring: object = None
    camera: tuple = (20.0, -60.0)  # (elevation, azimuth) in degrees, the view's
    marked: np.ndarray = field(default_factory=lambda: np.zeros(0, int))
    clips: list = field(default_factory=list)
    misses: dict = field(default_factory=dict)  # frame -> one line of keyframe misses
    stretch: np.ndarray | None = None  # (frames,) a cloth's largest spring stretch per frame
    velocities: np.ndarray | None = None  # (frames, n, 3) the particles' velocities

    @property
    def frames(self) -> int:
        return self.positions.shape[0]

    @property
    def times(self) -> np.ndarray:
        return self.dt * np.arange(self.frames)


def scene_of(problem, trajectory) -> Scene:
    """The :class:`Scene` of ``problem``'s ``trajectory``."""
    model, view = problem.model, problem.view
    times = trajectory.times
    scene = Scene(problem.name, float(trajectory.dt), points3(trajectory.x),
                  np.asarray(model.faces, int) if isinstance(model, Surface) else None,
                  bodies(model, times), targets(problem), dim=model.dim,
                  misses=misses(problem, trajectory), velocities=points3(trajectory.v))
    if isinstance(model, PhysicalReport):
        scene.stretch = np.array([model.max_stretch(x) for x in trajectory.x])
    if isinstance(view, FlockView):
        scene.highlight = view.highlight
    if isinstance(view, ClothView):
        scene.ring, scene.camera = view.ring, view.camera
    scene.marked = model.prescribed_particles()
    if isinstance(view, BlendView):
        scene.clips = [clip_of(view, kind, trajectory.steps, trajectory.dt)
                       for kind in ("fall", "walk")]
    return scene


def clip_of(view: BlendView, kind: str, steps: int, dt: float) -> Clip:
    """Source clip ``kind`` at the frames that go with the blend's ``0..steps``."""
    clip = view.clip(kind)
    frames = [view.clip_frame(kind, k, dt) for k in range(steps + 1)]
    if frames[0] < 0 or frames[-1] > clip.trajectory.steps:
        raise ValueError(f"the blend's frames need {kind} clip frames {frames[0]}..{frames[-1]}, "
                         f"outside 0..{clip.trajectory.steps}")
    times = np.array(frames) * clip.trajectory.dt
    return Clip(kind, points3(np.asarray(clip.trajectory.x)[frames]),
                bodies(clip.model, times, prefix=f"{kind}_"), times)


def misses(problem, trajectory) -> dict:
    """``{frame: "term: miss ...; ..."}`` at each keyframe frame."""
    by_frame: dict[int, list] = {}
    for term in problem.objective_terms.state_terms:
        by_frame.setdefault(int(term.frame), []).append(term.miss(trajectory))
    return {frame: format_misses(found) for frame, found in sorted(by_frame.items())}
