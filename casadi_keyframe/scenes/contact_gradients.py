"""Small scenes for checking gradients through every contact law against the forward pass.

A sheet (``rows x rows``, 0.6 m, 0.12 kg) lies on a body, ``"sliding"`` (thrown at 1.5 m/s
along it), or ``"sticking"``: landing on it from 1.5 cm above at 0.5 m/s with a slow slide
(0.1 m/s), which friction stops; under random per-step forces (the controls ``u`` the check
is made at) and Coulomb friction ``mu`` on the body; the objective is a centre of
mass keyframe, a state keyframe and smoothness.  The laws (:data:`LAWS`): the ground held by
the step alone (``"held"``: ``collision="constraint"``), the default guard (``"guarded"``),
the paper's springs alone (``"penalty"``: no friction), two sheets lying on each other
(``"self-contact"``, on the guarded ground), a big sphere rising and turning under the sheet
(``"moving"``) and an icosphere read as a mesh (``"mesh"``), both guarded.
"""
from __future__ import annotations

import numpy as np

from ..controls import StepForces
from ..integrators import LinearizedBackwardEuler
from ..models import ClothModel, Contact, MeshBody, Plane, Sphere
from ..objectives import CenterOfMassKeyframe, Smoothness, StateKeyframe
from ..problem import ControlProblem

LAWS = ("held", "guarded", "penalty", "self-contact", "moving", "mesh")
MOTIONS = ("sliding", "sticking")
FORCES = {"sliding": 0.03, "sticking": 0.003}  # N rms per particle and step: the controls
SIZE, MASS, SPEED, RADIUS = 0.6, 0.12, 1.5, 0.5  # m, kg, m/s, m (the sphere's and the mesh's)


def _turning(t):
    """A body rising at 0.2 m/s and turning about z at 1 rad/s."""
    c, s = np.cos(t), np.sin(t)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]]), np.array([0.0, 0.0, 0.2 * t])


def _body(law: str, contact: Contact):
    if law in ("moving", "mesh"):
        centre = np.array([0.0, 0.0, -RADIUS])
        if law == "moving":
            return Sphere(centre, RADIUS, contact=contact, motion=_turning)
        import trimesh
        ball = trimesh.creation.icosphere(subdivisions=2, radius=RADIUS)
        return MeshBody(np.asarray(ball.vertices) + centre, np.asarray(ball.faces),
                        contact=contact)
    return Plane((0.0, 0.0, 0.0), contact=contact)


def _sheet(law: str, rows: int, body, collision: str):
    """The model and its start positions: one sheet on the body's top (z = 0), or two, the
    second 2 cm above the first, turned a little, touching it through self-contact."""
    grid = ClothModel.grid(rows, rows, width=SIZE, height=SIZE, plane="xy", mass=MASS)
    x = grid.rest_positions - grid.rest_positions.mean(0) + [0, 0, body.contact.thickness]
    if law != "self-contact":
        return ClothModel.grid(rows, rows, width=SIZE, height=SIZE, plane="xy", mass=MASS,
                               colliders=[body], collision=collision), x
    a = np.radians(10)
    turn = np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1.0]])
    top = x @ turn.T + [0.05, 0.02, 0.02]
    model = ClothModel.from_mesh(np.vstack([x, top]), np.vstack([grid.faces,
                                                                 grid.faces + grid.n]),
                                 mass=2 * MASS, colliders=[body], collision=collision,
                                 self_contact=Contact(200.0, 0.5, 0.04, 0.02))
    return model, np.vstack([x, top])


def contact_gradient_problem(law: str, mu: float = 0.0, motion: str = "sliding", *,
                             rows: int = 4, steps: int = 8, seed: int = 0,
                             solver: str = "direct"):
    """``(problem, u)``: the scene of ``law`` (:data:`LAWS`) with friction ``mu`` on its
    body, ``motion`` one of :data:`MOTIONS`, ``steps`` at dt = 1/60, and the controls to
    check the gradient at (seeded random forces, :data:`FORCES`)."""
    if law not in LAWS or motion not in MOTIONS:
        raise ValueError(f"law must be one of {LAWS} and motion one of {MOTIONS}, got "
                         f"{law!r}, {motion!r}")
    collision = {"held": "constraint", "penalty": "penalty"}.get(law, "guarded")
    body = _body(law, Contact(friction=mu))
    model, x0 = _sheet(law, rows, body, collision)
    v0 = np.zeros_like(x0)
    if motion == "sliding":
        v0[:, 0] = SPEED
    else:
        x0 = x0 + [0.0, 0.0, 0.015]
        v0[:] = [0.1, 0.0, -0.5]
    target = x0.mean(0) + [0.3 if motion == "sliding" else 0.05, 0.1, 0.0]
    objective = (CenterOfMassKeyframe(steps, x=target) + StateKeyframe(steps // 2, x=x0 + 0.02)
                 + Smoothness(1e-4))
    prob = ControlProblem(model=model, integrator=LinearizedBackwardEuler(solver), x0=x0,
                          v0=v0, steps=steps, dt=1 / 60, controls=StepForces(),
                          objective=objective, name=f"{law} {motion} mu {mu:g}")
    u = FORCES[motion] * np.random.default_rng(seed).standard_normal(prob.size)
    return prob, u
