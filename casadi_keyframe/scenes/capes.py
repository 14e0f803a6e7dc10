r"""A cape on an animated character (fig. 6 of Wojtan et al. 2006) and its two source clips.

The cape is a rows x cols Choi-Ko sheet (26 x 16 by default, as in the paper: 1 m long,
0.6 m wide, 0.4 kg) whose top edge's middle part is sewn to the shoulder line of the
character's torso (an :class:`~.models.cloth.Attachment` following
:meth:`.skeleton.Character.shoulder_points`); the rest hangs down the back.  It collides
with every capsule of the body, the ground plane z = 0 and itself.

:func:`simulate_clip` makes the two passive source clips (zero control forces) that the
boundary-value problem stitches: the cape on a walking and on a falling character.  Each
clip starts from the cape hanging at rest from the first pose, settled by a short pre-roll
(the same animation played before t = 0), so the start state is near equilibrium.
"""
from __future__ import annotations

from functools import lru_cache

import numpy as np

from ..integrators import LinearizedBackwardEuler
from ..models import DEFAULT_COLLISION, Attachment, ClothModel, ClothParams
from ..models.contact.colliders import Contact, Plane
from ..simulate import simulate
from .animations import Animation, Walk, fall, walk
from .skeleton import Character

CAPE_PARAMS = ClothParams(stretch=500.0, shear=50.0, bend=2e-5, damping=0.5, air_drag=2.0)
"""Fabric at dt = 1/60: the default sheet's stiffnesses (about 1 % strain hanging) with

* ``air_drag = 2 /s``: a terminal speed g / 2 = 4.9 m/s, near that of a 0.4 kg, 0.6 m^2
  sheet (3.3 m/s with quadratic drag and C_d = 1).  With the default 0.1 the cape rides the
  body down and hits the ground at its 6-7 m/s landing speed, 11 cm per step against 1-2 cm
  contact layers, and its hem whips (stretch 2.3 on a 2 m fall); walking, it now streams
  back about 15 degrees, clear of the legs.
* ``damping = 0.5 N s/m`` per spring (``c dt / m ~ 8`` for the 1 g particles): fabric's
  internal friction; it damps only the rate of change of spring lengths, which at 0.02
  spiked to stretch 1.6-2.6 when the body landed (measured over four falls: 1.2-1.7 now).
"""

CLIPS = ("walk", "fall")


def cape_contacts(particle_mass: float, spacing: float, dt: float = 1 / 60,
                  stiffness: float = 50.0, damping: float = 1.0) -> dict[str, Contact]:
    """Contact laws for the body, the ground and self-contact, scaled by the particle mass.

    ``k = stiffness m / dt^2`` and ``c = damping k dt``: the same dimensionless contact at
    every resolution (``dt sqrt(k/m) = sqrt(stiffness)``), softer than the default
    :class:`Contact` on fine capes so that the linearized step stays mild, while a particle's
    weight still sinks it only ``g dt^2 / stiffness``; with ``c = k dt`` an implicit step
    removes about half a penetration and leaves no rebound.  Layers: 1.2 cm on the body,
    2 cm on the ground (fast cloth crosses 1 cm in a step), ``0.4 spacing`` between cloth
    particles (``spacing`` in m).  Measurements behind the choice: docs/problem_notes.md.
    """
    if not (particle_mass > 0 and spacing > 0 and dt > 0 and stiffness > 0 and damping >= 0):
        raise ValueError("cape_contacts needs positive particle_mass, spacing, dt, stiffness "
                         f"and damping >= 0, got {particle_mass}, {spacing}, {dt}, "
                         f"{stiffness}, {damping}")
    k = stiffness * particle_mass / dt ** 2
    c = damping * k * dt
    return {"body": Contact(k, c, thickness=0.012, width=0.006),
            "ground": Contact(k, c, thickness=0.02, width=0.01),
            "self": Contact(k, c, thickness=0.4 * spacing, width=0.2 * spacing)}


def cape_model(character: Character, animation: Animation, *, rows: int = 26, cols: int = 16,
               width: float = 0.6, length: float = 1.0, mass: float = 0.4,
               attach_width: float = 0.44, params: ClothParams | None = None,
               dt: float = 1 / 60, lead: float | None = None, contacts: dict | None = None,
               collision: str = DEFAULT_COLLISION, jit: bool | None = None,
               body: list | None = None) -> ClothModel:
    """The cape as a :class:`ClothModel` on ``character`` moving through ``animation``.

    Rest shape: a ``width`` x ``length`` sheet in the xz plane, top row (row 0) along x at
    z = 0; the top row's particles within ``attach_width / 2`` of its middle follow the
    shoulder line.  The body's capsules are where the body is (``lead`` s ahead, if given:
    under the paper's penalty springs, which see the body at a step's start, looking a step
    ahead kept a particle on a moving limb level with it; the default guard checks where the
    body is at the step's end).  ``contacts``: see :func:`cape_contacts`; ``collision``: how
    the body and the ground are touched (:class:`ClothModel`); ``body``: colliders in place
    of the character's capsules (its mesh: :mod:`.body_meshes`).
    """
    if int(rows) != rows or int(cols) != cols or rows < 2 or cols < 2:
        raise ValueError(f"a cape needs rows >= 2 and cols >= 2, got {rows} x {cols}")
    if not (width > 0 and length > 0 and attach_width > 0):
        raise ValueError(f"cape width, length and attach_width must be positive, got "
                         f"{width}, {length}, {attach_width}")
    x_top = np.linspace(-width / 2, width / 2, int(cols))
    attached = np.flatnonzero(np.abs(x_top) <= attach_width / 2 + 1e-9)
    if attached.size == 0:
        raise ValueError(f"attach_width {attach_width} m holds no particle of the top row "
                         f"(spacing {width / (cols - 1):.3g} m); widen it")
    if contacts is None:
        spacing = min(width / (cols - 1), length / (rows - 1))
        contacts = cape_contacts(mass / (rows * cols), spacing, dt)
    bodies = (character.capsules(animation, contacts["body"], lead=lead or 0.0)
              if body is None else list(body))
    path = character.shoulder_points(animation, x_top[attached])
    return ClothModel.grid(int(rows), int(cols), width=width, height=length, mass=mass,
                           params=params or CAPE_PARAMS, plane="xz", origin=(-width / 2, 0, 0),
                           colliders=[*bodies, Plane(contact=contacts["ground"])],
                           self_contact=contacts["self"],
                           attachments=[Attachment(attached, path)], collision=collision,
                           jit=jit)


def hanging_state(model: ClothModel, character: Character, animation: Animation,
                  t: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """``(x, v)``: the cape hanging straight down from the shoulder line at time t, every
    particle moving with the shoulders' mean velocity."""
    rest = model.rest_positions
    top = np.flatnonzero(np.isclose(rest[:, 2], rest[:, 2].max()))
    line = character.shoulder_points(animation, rest[top, 0])
    h = 1e-4
    x = line(t)[np.searchsorted(rest[top, 0], rest[:, 0])]
    x[:, 2] += rest[:, 2] - rest[:, 2].max()
    v = (line(t + h) - line(t - h)).mean(axis=0) / (2 * h)
    return x, np.tile(v, (model.n, 1))


def settled_state(character: Character, animation: Animation, *, preroll: float,
                  dt: float = 1 / 60, **cape) -> tuple[np.ndarray, np.ndarray]:
    """The cape's state at t = 0 after hanging from the shoulders for ``preroll`` s of the
    animation before t = 0 (starting straight, moving with the shoulders)."""
    steps = int(round(preroll / dt))
    if steps == 0:
        model = cape_model(character, animation, dt=dt, **cape)
        return hanging_state(model, character, animation, 0.0)
    early = animation.shifted(steps * dt)
    model = cape_model(character, early, dt=dt, **cape)
    x0, v0 = hanging_state(model, character, early, 0.0)
    traj = simulate(LinearizedBackwardEuler(), model, x0, v0, np.zeros((steps, model.n, 3)), dt)
    return traj.x[-1], traj.v[-1]


def simulate_clip(kind="walk", rows: int = 26, cols: int = 16, seconds: float = 2.0,
                  dt: float = 1 / 60, *, preroll: float | None = None,
                  character: Character | None = None, **cape):
    """A passive source clip: ``(model, Trajectory, animation)``, the cape on a character
    that walks (``kind="walk"``), falls (``"fall"``) or follows any :class:`Animation`.

    The trajectory starts (frame 0, t = 0) from the cape settled by a ``preroll`` (default
    one walk period, else 0.5 s: standing still before a fall) and runs ``seconds`` with
    zero control forces.  ``cape`` goes to :func:`cape_model` (mass, width, params, ...).
    """
    character = character or Character()
    if isinstance(kind, Animation):
        animation = kind
    elif kind in CLIPS:
        animation = {"walk": walk, "fall": fall}[kind](character)
    else:
        raise ValueError(f"kind must be one of {CLIPS} or an Animation, got {kind!r}")
    if not (seconds > 0 and dt > 0):
        raise ValueError(f"seconds and dt must be positive, got {seconds}, {dt}")
    if preroll is None:
        preroll = animation.period if isinstance(animation, Walk) else 0.5
    if preroll < 0:
        raise ValueError(f"preroll must be >= 0 s, got {preroll}")
    x0, v0 = settled_state(character, animation, preroll=preroll, dt=dt, rows=rows, cols=cols,
                           **cape)
    model = cape_model(character, animation, rows=rows, cols=cols, dt=dt, **cape)
    steps = int(round(seconds / dt))
    traj = simulate(LinearizedBackwardEuler(), model, x0, v0, np.zeros((steps, model.n, 3)), dt)
    return model, traj, animation


@lru_cache(maxsize=8)
def cached_clip(kind: str, rows: int, cols: int, seconds: float, dt: float):
    """:func:`simulate_clip` with the default character and cape, memoised per argument set
    for the process (problem files are re-imported at every load, so their own caches do
    not last).  The result is shared: read it, never modify its arrays."""
    return simulate_clip(kind, rows, cols, seconds=seconds, dt=dt)


def clip_report(model: ClothModel, traj) -> dict:
    """Figures of a clip: the largest spring stretch, the deepest particle inside the body
    or the ground (m: the library's one measure, :meth:`ClothModel.physical_report`) and how
    far a particle is below z = 0."""
    physical = model.physical_report(traj.x, traj.dt)
    return {"max_stretch": physical["max_stretch"],
            "penetration": physical.get("max_penetration", 0.0),
            "below_ground": max(0.0, -float(traj.x[:, :, 2].min()))}
