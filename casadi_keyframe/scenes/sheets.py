"""The hanging test sheet: a square of cloth pinned at its top corners and swung forward to
keyframes, the small cloth case of the studies, the tests and the benchmarks."""
from __future__ import annotations

import numpy as np

from ..checks import frame_at
from ..controls import StepForces
from ..integrators import LinearizedBackwardEuler
from ..models import DEFAULT_COLLISION, ClothModel, ClothParams
from ..models.contact.colliders import Plane
from ..objectives import CenterOfMassKeyframe, Smoothness, StateKeyframe
from ..problem import ControlProblem


def hanging_sheet(rows: int = 5, stretch: float = 500.0, ground: bool = True,
                  colliders=(), collision: str = DEFAULT_COLLISION) -> ClothModel:
    """A 1 m, 1 kg sheet of rows x rows particles pinned at its top corners, its lower edge
    resting on the ground if ``ground``, with any further ``colliders`` (touched as
    ``collision`` says: held by the step, or the paper's penalty springs)."""
    colliders = [*([Plane((0, 0, -1.007))] if ground else []), *colliders]
    return ClothModel.grid(rows, rows, pinned=[0, rows - 1], colliders=colliders,
                           params=ClothParams(stretch=stretch, shear=stretch / 10),
                           collision=collision)


def swing_problem(model: ClothModel, steps: int, dt: float, integrator, *,
                  reach=(0.0, 0.2, 0.05), midway=(0.0, 0.1, 0.0), controls=None,
                  name: str = "hanging_sheet") -> ControlProblem:
    """``model`` swung forward from rest: every particle ``reach`` (m) from its rest position
    at the last frame, the centre of mass ``midway`` from its rest at half time, by smooth
    step forces (on every particle unless ``controls`` says otherwise)."""
    x0 = model.rest_positions
    objective = (StateKeyframe(steps, x=x0 + reach)
                 + CenterOfMassKeyframe(steps // 2, x=x0.mean(0) + midway)
                 + Smoothness(1e-4))
    return ControlProblem(model=model, integrator=integrator, x0=x0, v0=np.zeros_like(x0),
                          steps=steps, dt=dt, controls=controls or StepForces(),
                          objective=objective, name=name)


def contact_problem(dt: float = 1 / 60, horizon: float = 1 / 3, stretch: float = 500.0,
                    rows: int = 5, solver: str = "direct", controls=None,
                    collision: str = DEFAULT_COLLISION) -> ControlProblem:
    """The gradient-accuracy case: :func:`hanging_sheet`, resting on the ground, swung
    forward (:func:`swing_problem`) over ``horizon`` s."""
    steps = frame_at(horizon, dt, "contact_problem: the horizon")
    if steps < 2:
        raise ValueError(f"contact_problem: dt = {dt} must divide the horizon {horizon} s into "
                         ">= 2 steps")
    return swing_problem(hanging_sheet(rows, stretch, collision=collision), steps, dt,
                         LinearizedBackwardEuler(solver), controls=controls,
                         name="contact_sheet")
