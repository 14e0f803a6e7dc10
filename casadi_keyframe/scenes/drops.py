"""Free drops: a sheet thrown onto a body at a given speed, no controls, the test of contact
that holds (how deep the sheet gets into the body, how far its springs stretch, whether it
blows up) for each way the cloth touches bodies.

The sheet is ``size`` m square, 0.3 kg, ``rows x rows`` particles, lying flat (or tilted by
``tilt`` degrees about its x axis) with its lowest point ``gap`` m above the body, moving
straight down at ``speed`` m/s.  Bodies: the ground (a plane), a sphere and a horizontal
capsule under the sheet's centre, still, rising into the sheet at 2 m/s ("rising sphere",
"rising capsule") or swinging up into it about one end at 3 rad/s ("swinging capsule").
:func:`mesh_drop` drops the sheet on an icosphere read from an OBJ file (a
:class:`~..models.contact.colliders.MeshBody`) and on the analytic sphere it approximates.

:func:`slope_slide` and :func:`ground_throw` are friction's analytic checks.
"""
from __future__ import annotations

from pathlib import Path
from tempfile import TemporaryDirectory

import numpy as np

from ..export.obj import write_obj
from ..integrators import LinearizedBackwardEuler
from ..models import (DEFAULT_COLLISION, Capsule, ClothModel, ClothParams, Contact, MeshBody,
                      Plane, Sphere)
from ..simulate import simulate
from ..state import SimulationError

BODIES = ("ground", "sphere", "capsule", "rising sphere", "rising capsule", "swinging capsule")
RISE = 2.0  # m/s
SWING = 3.0  # rad/s
MESH_RADIUS = 0.3  # m: the icosphere's


def drop_model(rows: int, body, collision: str, size: float = 1.0):
    """The sheet and ``body`` (one of :data:`BODIES`, or a body) under its centre."""
    if not isinstance(body, str):
        return ClothModel.grid(rows, rows, width=size, height=size, plane="xy", mass=0.3,
                               colliders=[body], collision=collision)
    if body not in BODIES:
        raise ValueError(f"drop: body must be one of {BODIES}, got {body!r}")
    centre = np.array([size / 2, size / 2, 0.0])
    up = np.array([0.0, 0.0, RISE])
    bodies = {"ground": lambda: Plane((0.0, 0.0, 0.0)),
              "sphere": lambda: Sphere(centre - [0, 0, 0.25], 0.25),
              "capsule": lambda: Capsule(centre - [0.3, 0, 0.08], centre + [0.3, 0, -0.08],
                                         0.08),
              "rising sphere": lambda: Sphere(lambda t: centre - [0, 0, 0.25] + up * t, 0.25),
              "rising capsule": lambda: Capsule(lambda t: centre - [0.3, 0, 0.08] + up * t,
                                                lambda t: centre + [0.3, 0, -0.08] + up * t,
                                                0.08),
              "swinging capsule": lambda: Capsule(
                  centre - [0.3, 0, 0.08], lambda t: centre + [0.6 * np.cos(SWING * t) - 0.3,
                                                               0, 0.6 * np.sin(SWING * t) - 0.08],
                  0.08)}
    return ClothModel.grid(rows, rows, width=size, height=size, plane="xy", mass=0.3,
                           colliders=[bodies[body]()], collision=collision)


def drop_start(model, speed: float, tilt: float = 0.0, gap: float = 0.03):
    """``(x0, v0)``: the sheet tilted by ``tilt`` degrees about the x axis through its centre,
    its lowest particle ``gap`` m above z = 0 (the top of every body here), all moving down
    at ``speed`` m/s."""
    x = model.rest_positions.copy()
    centre = x.mean(axis=0)
    a = np.radians(tilt)
    turn = np.array([[1, 0, 0], [0, np.cos(a), -np.sin(a)], [0, np.sin(a), np.cos(a)]])
    x = (x - centre) @ turn.T + centre
    x[:, 2] += gap - x[:, 2].min()
    v = np.zeros_like(x)
    v[:, 2] = -speed
    return x, v


def drop(rows: int, body, speed: float, *, tilt: float = 0.0,
         collision: str = DEFAULT_COLLISION, dt: float = 1 / 60, duration: float = 0.5,
         solver: str = "auto"):
    """Simulate a drop: ``(problem-free trajectory or None, report)``; the report has the
    deepest particle inside the body over all frames (m, and its frame), the largest spring
    stretch, and ``failed`` (the simulation's error) when it blew up."""
    model = drop_model(rows, body, collision)
    x0, v0 = drop_start(model, speed, tilt)
    steps = int(round(duration / dt))
    integrator = LinearizedBackwardEuler(solver)
    try:
        traj = simulate(integrator, model, x0, v0, np.zeros((steps, model.n, 3)), dt)
    except SimulationError as err:
        return None, {"failed": str(err)}
    return traj, model.physical_report(traj.x, dt)


def icosphere_file(folder, radius: float = MESH_RADIUS, subdivisions: int = 4) -> Path:
    """An icosphere of ``radius`` about the origin (2,562 vertices at 4 subdivisions) written
    as an OBJ file in ``folder``."""
    import trimesh
    ball = trimesh.creation.icosphere(subdivisions=subdivisions, radius=radius)
    return write_obj(Path(folder) / f"icosphere_{subdivisions}.obj", ball.vertices, ball.faces)


def mesh_drop(rows: int, speed: float, *, rising: bool = False,
              collision: str = DEFAULT_COLLISION, dt: float = 1 / 60, duration: float = 0.5,
              subdivisions: int = 4) -> dict:
    """The sheet dropped at ``speed`` onto an icosphere of radius :data:`MESH_RADIUS` read
    from an OBJ file (still, or rising at :data:`RISE` by its motion), and onto the analytic
    :class:`Sphere`: per run the deepest particle inside the true sphere over all frames
    (``inside``, m), the largest stretch, and the largest distance between the two runs'
    centres of mass at any frame (``com``, m); ``failed`` if a run blew up."""
    centre = np.array([0.5, 0.5, -MESH_RADIUS])
    place = ((lambda t: centre + [0, 0, RISE * t]) if rising else (lambda t: centre))
    with TemporaryDirectory() as folder:
        mesh = MeshBody.from_file(icosphere_file(folder, subdivisions=subdivisions),
                                  motion=lambda t: (np.eye(3), place(t)))
    if not rising:  # a still body: no motion, so the hold is on its surface as the sphere's
        mesh = MeshBody(mesh.vertices + centre, mesh.faces, source=mesh.source)
    out = {}
    for name, body in (("mesh", mesh), ("sphere", Sphere(place if rising else centre,
                                                        MESH_RADIUS))):
        traj, report = drop(rows, body, speed, collision=collision, dt=dt, duration=duration)
        if traj is None:
            return {"failed": f"{name}: {report['failed']}"}
        gap = [MESH_RADIUS - np.linalg.norm(x - place(k * dt), axis=1).min()
               for k, x in enumerate(traj.x)]
        out[name] = {"inside": max(gap), "stretch": report["max_stretch"],
                     "com": traj.x.mean(axis=1)}
    out["com"] = float(np.linalg.norm(out["mesh"]["com"] - out["sphere"]["com"], axis=1).max())
    return out


def slope_slide(mu: float, angle: float = 20.0, collision: str = DEFAULT_COLLISION,
                seconds: float = 1.0, dt: float = 1 / 60) -> tuple[float, float]:
    """``(slid, analytic)``: how far (m) a 0.5 m sheet resting on a slope of ``angle``
    degrees with friction ``mu`` slides in ``seconds``, and Coulomb's
    ``g (sin - mu cos) t^2 / 2`` (0 where ``mu >= tan``), without air drag."""
    a = np.radians(angle)
    normal = np.array([0.0, -np.sin(a), np.cos(a)])
    ground = Plane((0, 0, 0), normal, contact=Contact(friction=mu))
    model, x0 = _resting_sheet(ground, collision, a)
    traj = simulate(LinearizedBackwardEuler(), model, x0, np.zeros_like(x0),
                    np.zeros((int(round(seconds / dt)), model.n, 3)), dt)
    down = np.array([0.0, -np.cos(a), -np.sin(a)])
    g = -ClothParams().gravity[2]
    return (float((traj.x[-1] - traj.x[0]).mean(0) @ down),
            max(0.0, g * (np.sin(a) - mu * np.cos(a))) * seconds ** 2 / 2)


def ground_throw(mu: float, speed: float, collision: str = DEFAULT_COLLISION,
                 dt: float = 1 / 60) -> tuple[float, float]:
    """``(travelled, analytic)``: how far (m) a 0.5 m sheet resting on the ground and thrown
    along it at ``speed`` m/s slides before it stops, and ``v^2 / (2 mu g)``."""
    ground = Plane((0, 0, 0), contact=Contact(friction=mu))
    model, x0 = _resting_sheet(ground, collision, 0.0)
    v0 = np.zeros_like(x0)
    v0[:, 0] = speed
    g = -ClothParams().gravity[2]
    steps = int((speed / (mu * g) + 0.2) / dt)
    traj = simulate(LinearizedBackwardEuler(), model, x0, v0, np.zeros((steps, model.n, 3)), dt)
    return float(traj.x[-1, :, 0].mean() - x0[:, 0].mean()), speed ** 2 / (2 * mu * g)


def _resting_sheet(ground, collision, angle, rows: int = 8):
    """A 0.5 m, 0.3 kg sheet without air drag lying on ``ground`` (tilted by ``angle``
    rad): on the hold's layer, or as deep in the penalty layer as its weight sinks it."""
    model = ClothModel.grid(rows, rows, width=0.5, height=0.5, plane="xy", mass=0.3,
                            colliders=[ground], collision=collision,
                            params=ClothParams(air_drag=0.0))
    c, g = ground.contact, -ClothParams().gravity[2]
    sink = 0.0
    if collision == "guarded":
        sink = np.sqrt(2 * c.width * model.masses.max() * g * np.cos(angle) / c.stiffness)
    turn = np.array([[1, 0, 0], [0, np.cos(angle), -np.sin(angle)],
                     [0, np.sin(angle), np.cos(angle)]])
    x = (model.rest_positions - model.rest_positions.mean(0)) @ turn.T
    return model, x + ground.normal / np.linalg.norm(ground.normal) * (c.thickness - sink)
