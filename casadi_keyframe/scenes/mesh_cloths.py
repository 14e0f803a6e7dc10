"""A cloth keyframe problem from mesh files, with every bad input refused by the name of the
option that gave it (what ``problems/mesh_keyframes.py`` builds from its overrides).

The option names in messages are the problem file's: ``cloth``, ``keyframes``, ``pins``,
``pin_group``, ``pin_box``, ``pin_motion``, ``pin_body``, ``steps``, ``spheres``,
``bodies``.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..controls import InitialVelocity, StepForces
from .. import progress
from ..loading import OverrideError
from ..objectives import MeshKeyframe
from ..meshes import Mesh, MeshError, PinBox, pin_indices, read_mesh
from ..models import Attachment, ClothModel, ClothParams
from ..models.contact.colliders import Plane, Sphere
from ..objectives import Smoothness, StrainLimit
from ..views import ClothView
from .body_meshes import read_body
from .cape_tracking import tracking_forces
from .cloths import cloth_problem
from .pin_paths import RiddenPath, sampled_pins, start_gap_note
from ..objectives.paths import keyframe_path

PROBLEM = "mesh_keyframes"
EXAMPLE = "40:wave.obj,80:fold.obj"
AIM_RUNS = 2  # guess "aim": the tracking controller's learning runs before the one it keeps
EFFORTS = ("acceleration", "force")  # the control cost's measure of per-step forces


def refuse(option: str, message: str):
    """An :class:`~..loading.OverrideError` naming ``option`` (the CLI exits 2 with it)."""
    return OverrideError(f"{PROBLEM}: {option}: {message}", PROBLEM, listed=False)


def parse_keyframes(text: str) -> list[tuple[int, str]]:
    """``"40:wave.obj,80:fold.obj"`` -> ``[(40, "wave.obj"), (80, "fold.obj")]``, frames
    increasing, each at most once."""
    out = []
    for item in (p.strip() for p in str(text).split(",")):
        frame, sep, path = item.partition(":")
        if not sep or not path.strip() or not frame.strip().isdigit():
            raise refuse("keyframes", f"expected FRAME:FILE pairs separated by commas, such as "
                                      f"{EXAMPLE}; got {item!r}")
        out.append((int(frame), path.strip()))
    frames = [f for f, _ in out]
    if min(frames) < 1 or len(set(frames)) != len(frames):
        raise refuse("keyframes", f"frames must be 1 or more and each given once, got {frames}")
    return sorted(out)


def read_option(option: str, path) -> Mesh:
    """The mesh file an option names, its reading errors refused by the option's name and
    its notices (quads triangulated...) printed as notes."""
    try:
        mesh = read_mesh(Path(path).expanduser())
    except MeshError as err:
        raise refuse(option, str(err)) from None
    for notice in mesh.notices:
        progress.note(notice)
    return mesh


def pinned_of(mesh: Mesh, pins, pin_group, pin_box):
    """The pinned vertices the three pin options name together (their union)."""
    chosen = [np.zeros(0, np.intp)]
    for option, value in (("pins", pins), ("pin_group", pin_group), ("pin_box", pin_box)):
        if value is None or (option == "pins" and len(value) == 0):
            continue
        try:
            if option == "pin_box":
                if len(value) != 6:
                    raise MeshError(f"give 6 numbers, the lower corner x,y,z then the upper "
                                    f"x,y,z; got {len(value)}")
                value = PinBox(value[:3], value[3:])
            chosen.append(pin_indices(mesh, value))
        except MeshError as err:
            raise refuse(option, str(err)) from None
    return np.unique(np.concatenate(chosen))


def targets_of(model, keyframes, steps, *, weight, align, cloth=None,
               tolerance=None) -> list[MeshKeyframe]:
    """One :class:`MeshKeyframe` per ``(frame, file)``, each checked against the cloth's
    vertices and faces and the horizon here, so the message names the option; a target
    that is the ``cloth``'s own file is refused (a mistyped name, most likely).
    ``tolerance``: the rms position miss each counts as met (None: the keyframes' default,
    1 % of the target's extent)."""
    terms = []
    for frame, target in keyframes:
        path = target.label() if isinstance(target, Mesh) else target
        if frame > steps:
            raise refuse("keyframes", f"frame {frame} ({path}) is beyond the horizon of "
                                      f"steps={steps}; pick a frame in 1..{steps} or raise steps")
        if _same_file(target, cloth):
            raise refuse("keyframes", f"frame {frame}'s target {path} is the cloth file "
                                      "itself: give the file of the shape the cloth should "
                                      "take (to ask for the rest shape, export a copy)")
        mesh = target if isinstance(target, Mesh) else read_option("keyframes", target)
        if mesh.n != model.n:
            raise refuse("keyframes", f"the target {path} (frame {frame}) has {mesh.n} "
                                      f"vertices, the cloth {model.n}; a target must be the "
                                      f"cloth's mesh in another shape")
        if not mesh.same_topology(model.faces):
            raise refuse("keyframes", f"the target {path} (frame {frame}) has the cloth's "
                                      f"{model.n} vertices but other faces; export it from the "
                                      f"cloth's own mesh")
        terms.append(MeshKeyframe(frame, mesh, weight=weight / model.n, align=align,
                                  tolerance=tolerance))
    return terms


def _same_file(target, cloth) -> bool:
    """Whether a keyframe's target names the file the cloth was read from."""
    if cloth is None or getattr(cloth, "source", None) is None:
        return False
    path = target.source if isinstance(target, Mesh) else target
    return path is not None and Path(path).expanduser().resolve() == Path(
        cloth.source).resolve()


def colliders_of(ground, spheres) -> list:
    """A ground plane at height ``ground`` (None: none) and spheres from a flat list of
    ``x, y, z, radius`` numbers."""
    bodies = [] if ground is None else [Plane((0.0, 0.0, ground))]
    if spheres:
        if len(spheres) % 4:
            raise refuse("spheres", f"give x,y,z,radius for each sphere (a multiple of 4 "
                                    f"numbers), got {len(spheres)} numbers")
        for x, y, z, r in np.reshape(spheres, (-1, 4)):
            if not r > 0:
                raise refuse("spheres", f"a sphere's radius must be positive, got {r}")
            bodies.append(Sphere((x, y, z), float(r)))
    return bodies


def bodies_of(files, dt: float) -> list:
    """A :class:`~..models.MeshBody` per mesh file of ``files`` ("body.obj,arm.pc2": OBJ,
    PLY, USD, or a PC2 cache beside its ``NAME_rest.obj``, one cache frame per ``dt``),
    each read by :func:`~.body_meshes.read_body` (its notes printed)."""
    out = []
    for item in (p.strip() for p in str(files).split(",")):
        if not item:
            raise refuse("bodies", "give mesh files separated by commas, e.g. "
                                   "bodies=body.obj,arm.pc2")
        try:
            out.append(read_body(item, dt))
        except (MeshError, ImportError, ValueError) as err:
            message = str(err)
            raise refuse("bodies", message if item in message else f"{item}: {message}") \
                from None
    return out


def pin_body_of(value, bodies: list):
    """The body of ``bodies`` (the ``bodies`` option's, in its order) that ``pin_body``
    names: its index from 0, or its file's name without the extension."""
    stems = [Path(b.source).stem if getattr(b, "source", None) else "" for b in bodies]
    if not bodies:
        raise refuse("pin_body", "names a body of the bodies option, which gives none: add "
                                 "bodies=FILE (the body the pins ride on)")
    text = str(value).strip()
    if text.lstrip("-").isdigit():
        k = int(text)
        if not 0 <= k < len(bodies):
            raise refuse("pin_body", f"{k} is no body: bodies gives {len(bodies)}, indices "
                                     f"0..{len(bodies) - 1} ({', '.join(stems)})")
        return bodies[k]
    if stems.count(text) != 1:
        found = "two bodies have that name: give its index" if text in stems else "no body"
        raise refuse("pin_body", f"{text!r}: {found}; give an index 0..{len(bodies) - 1} or "
                                 f"one of {', '.join(stems)}")
    return bodies[stems.index(text)]


def moving_pins(cloth: Mesh, pinned, steps: int, dt: float, pin_motion=None,
                pin_body=None) -> Attachment | None:
    """The :class:`~..models.Attachment` that leads the ``pinned`` vertices along
    ``pin_motion`` (a time-sampled mesh file of the cloth: :func:`~.pin_paths.sampled_pins`)
    or on ``pin_body`` (a MeshBody: :class:`~.pin_paths.RiddenPath`); None when neither is
    given (the pins stay put).  Its notes (frames cut, a start away from the cloth's file)
    are printed."""
    if pin_motion is not None and pin_body is not None:
        raise refuse("pin_body", "and pin_motion both move the pins: give one (pin_motion: "
                                 "the pins follow a file; pin_body: they ride on a body)")
    option = "pin_motion" if pin_motion is not None else "pin_body"
    if pin_motion is None and pin_body is None:
        return None
    if len(pinned) == 0:
        raise refuse(option, "moves the pinned vertices, and none is pinned: name them with "
                             "pins, pin_group or pin_box")
    notes = []
    if pin_motion is not None:
        try:
            path, notes = sampled_pins(pin_motion, cloth.n, pinned, steps, dt)
        except (MeshError, ImportError, ValueError) as err:
            raise refuse("pin_motion", str(err)) from None
    else:
        path = RiddenPath(pin_body, cloth.vertices[pinned])
    for note in notes + start_gap_note(path(0.0), cloth.vertices, pinned, option):
        progress.note(note)
    return Attachment(pinned, path)


def wrinkled(model, depth: float) -> np.ndarray:
    """The cloth's rest positions moved ``depth`` metres along each vertex's normal times
    ``sin(pi a) sin(pi b)``, (a, b) the vertex's place in the mesh's two widest directions
    scaled to [0, 1]; pinned vertices stay.  An exactly flat sheet that hangs in its plane
    is compressed across its width as it sags, and a flat compressed mass-spring sheet is a
    buckling saddle: the planar motion is exact but unstable, so the exact gradient along
    it grows like e^(rate t), the rate rising as the mesh gets finer.  A start a hair out of
    plane buckles as real cloth does and keeps the gradient meaningful."""
    x = model.rest_positions
    if depth == 0:
        return x.copy()
    faces = model.faces
    normal = np.cross(x[faces[:, 1]] - x[faces[:, 0]], x[faces[:, 2]] - x[faces[:, 0]])
    at_vertex = np.zeros_like(x)
    for k in range(3):
        np.add.at(at_vertex, faces[:, k], normal)
    at_vertex /= np.maximum(np.linalg.norm(at_vertex, axis=1, keepdims=True), 1e-300)
    centred = x - x.mean(0)
    axes = np.linalg.svd(centred, full_matrices=False)[2][:2]
    span = centred @ axes.T
    ab = (span - span.min(0)) / np.maximum(np.ptp(span, axis=0), 1e-300)
    bump = depth * np.sin(np.pi * ab[:, 0]) * np.sin(np.pi * ab[:, 1])
    bump[~model.free_mask()[::3]] = 0.0
    return x + bump[:, None] * at_vertex


def tracking_guess(prob, land: bool = True, aim: int = 0) -> np.ndarray:
    """Start controls of ``prob`` (per-step forces): a PD controller pulling every particle
    along :func:`keyframe_path` (``cape_tracking.tracking_forces``) and, with ``land``,
    landing on each target at rest by two inverse steps, so the search starts on its
    keyframes.  The landings hold each target's shape whatever it costs: strong forces where
    a target stretches the cloth; the PD controller alone is gentle but lags.  ``aim`` > 0
    (without ``land``) runs the controller that many times more, each run's path aimed past
    each target by the miss the run before left there (iterative learning control: the
    springs' lag is taken out, the forces stay a controller's)."""
    terms = sorted(prob.objective_terms.state_terms, key=lambda t: t.frame)
    if land:
        stops = {t.frame: (t.position_target, np.zeros_like(prob.x0)) for t in terms
                 if not getattr(t, "align", False)}
        forces = tracking_forces(prob, keyframe_path(prob.x0, terms, prob.steps), stops=stops)
        return forces[:, prob.controls.idx].ravel()
    aims = [t.position_target for t in terms]
    for _ in range(aim):
        x = prob.simulate(_tracked(prob, terms, aims), records=False).x
        aims = [a if getattr(t, "align", False) else a + t.position_target - x[t.frame]
                for t, a in zip(terms, aims)]
    return _tracked(prob, terms, aims)


@dataclass(frozen=True)
class TrackingGuess:
    """:func:`tracking_guess` as a problem's guess rule: made when the search first asks,
    for whichever problem asks (the whole shot, or the frames after a kept one)."""

    land: bool = True
    aim: int = 0

    def __call__(self, prob) -> np.ndarray:
        return tracking_guess(prob, land=self.land, aim=self.aim)


def _tracked(prob, terms, aims) -> np.ndarray:
    """The PD controller's forces along the path through ``aims``, as ``prob``'s controls."""
    forces = tracking_forces(prob, keyframe_path(prob.x0, terms, prob.steps, aims))
    return forces[:, prob.controls.idx].ravel()


def mesh_keyframe_problem(*, cloth: Mesh, keyframes, steps, dt, mass, pinned, control,
                          colliders, weight, alpha, align, strain_limit, strain_weight,
                          smoothing=None, wrinkle=0.0, guess="aim", rest_band=0.0,
                          pin_motion=None, pin_body=None, effort="acceleration",
                          tolerance=None):
    """The control problem: the cloth hangs from ``pinned`` and starts at rest in the
    file's shape (``wrinkle`` metres out of it, see :func:`wrinkled`); per-step forces (or
    initial velocities) on the free particles aim at each :class:`MeshKeyframe`, with a
    strain limit and a small control cost; with ``guess`` "land", "track" or "aim"
    (per-step forces) the search starts from :func:`tracking_guess` with its landings,
    without, or aimed by :data:`AIM_RUNS` learning runs, with "none" from zero forces;
    ``rest_band`` the springs' rest band in the step (:class:`~..models.ClothParams`);
    ``pin_motion`` or ``pin_body``: the pinned vertices move (:func:`moving_pins`), start
    where their path starts and at the velocity of its first step; ``effort`` the control
    cost's measure of per-step forces, "acceleration" (each force over its particle's mass:
    :meth:`~..objectives.Smoothness.in_accelerations`) or "force" (the paper's);
    ``tolerance`` the keyframes' (:func:`targets_of`)."""
    steps = max(f for f, _ in keyframes) if steps is None else steps
    moving = moving_pins(cloth, pinned, steps, dt, pin_motion, pin_body)
    model = ClothModel.from_file(cloth, pinned=pinned if moving is None else (), mass=mass,
                                 colliders=colliders, params=ClothParams(rest_band=rest_band),
                                 attachments=() if moving is None else (moving,))
    terms = targets_of(model, keyframes, steps, weight=weight, align=align, cloth=cloth,
                       tolerance=tolerance)
    free = np.flatnonzero(model.free_mask()[::3])
    if free.size == 0:
        raise refuse("pins", "every vertex is pinned: nothing can move")
    controls = (StepForces(agents=free, smoothing=smoothing) if control == "forces"
                else InitialVelocity(agents=free, smoothing=smoothing))
    if effort not in EFFORTS:
        raise refuse("effort", f"give one of {', '.join(EFFORTS)}, got {effort!r}")
    smooth = (Smoothness.in_accelerations(alpha, model.masses[free])
              if effort == "acceleration" and control == "forces" else Smoothness(alpha))
    objective = sum(terms, smooth + StrainLimit(strain_limit, strain_weight))
    x0, v0 = wrinkled(model, wrinkle), np.zeros((model.n, 3))
    if moving is not None:
        x0[pinned] = moving.positions(0.0)
        v0[pinned] = (moving.positions(dt) - x0[pinned]) / dt
    prob = cloth_problem(model=model, steps=steps, dt=dt, objective=objective, x0=x0, v0=v0,
                         name=PROBLEM, controls=controls,
                         view=ClothView(camera=(15, -30)),
                         inputs=[m.source for m in (cloth, *(t.mesh for t in terms), *colliders)
                                 if getattr(m, "source", None) is not None]
                         + ([] if pin_motion is None else [pin_motion]))
    if guess == "none" or control != "forces":
        return prob
    return prob.with_guess(TrackingGuess(land=guess == "land",
                                         aim=AIM_RUNS if guess == "aim" else 0))
