"""Free drops: a sheet thrown onto a body at a given speed, no controls, the test of contact
that holds (how deep the sheet gets into the body, how far its springs stretch, whether it
blows up) for each way the cloth touches bodies.

The sheet is ``size`` m square, 0.3 kg, ``rows x rows`` particles, lying flat (or tilted by
``tilt`` degrees about its x axis) with its lowest point ``gap`` m above the body, moving
straight down at ``speed`` m/s.  Bodies: the ground (a plane), a sphere and a horizontal
capsule under the sheet's centre.
"""
from __future__ import annotations

import numpy as np

from ..integrators import LinearizedBackwardEuler
from ..models import DEFAULT_COLLISION, Capsule, ClothModel, Plane, Sphere
from ..state import SimulationError

BODIES = ("ground", "sphere", "capsule")


def drop_model(rows: int, body: str, collision: str, size: float = 1.0):
    """The sheet and ``body`` ("ground", "sphere" or "capsule") under its centre."""
    if body not in BODIES:
        raise ValueError(f"drop: body must be one of {BODIES}, got {body!r}")
    centre = np.array([size / 2, size / 2, 0.0])
    bodies = {"ground": lambda: Plane((0.0, 0.0, 0.0)),
              "sphere": lambda: Sphere(centre - [0, 0, 0.25], 0.25),
              "capsule": lambda: Capsule(centre - [0.3, 0, 0.08], centre + [0.3, 0, -0.08],
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


def drop(rows: int, body: str, speed: float, *, tilt: float = 0.0,
         collision: str = DEFAULT_COLLISION, dt: float = 1 / 60, duration: float = 0.5,
         solver: str = "auto"):
    """Simulate a drop: ``(problem-free trajectory or None, report)``; the report has the
    deepest particle inside the body over all frames (m, and its frame), the largest spring
    stretch, and ``failed`` (the simulation's error) when it blew up."""
    from ..simulate import simulate

    model = drop_model(rows, body, collision)
    x0, v0 = drop_start(model, speed, tilt)
    steps = int(round(duration / dt))
    integrator = LinearizedBackwardEuler(solver)
    try:
        traj = simulate(integrator, model, x0, v0, np.zeros((steps, model.n, 3)), dt)
    except SimulationError as err:
        return None, {"failed": str(err)}
    return traj, model.physical_report(traj.x, dt)
