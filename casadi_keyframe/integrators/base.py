r"""The contract of a time-stepping scheme: one step, its backward step and its tangent step.

A scheme maps the state ``s_n = (x_n, v_n)`` and the external force ``e_n`` of step n (stored
forces such as a flock's wander, plus the controls) to ``s_{n+1} = S_n(s_n, e_n)``.  It never loops over
time: :mod:`casadi_keyframe.simulate` owns the forward loop and the backward loop (eq. 5),
and the gradient strategies (:mod:`casadi_keyframe.adjoints`) choose which backward step
runs.  Its three numeric methods share their arguments:

Arguments:
    model: the particle system (a :class:`~casadi_keyframe.models.base.Model` with the
        capability the scheme names in ``requires``).
    state / start, end: :class:`~casadi_keyframe.state.State` at frames n and n+1.
    external: the external force of step n, ``(particles, dim)`` newtons.
    n, dt: the step's index (it starts at ``t = n dt``) and its size in seconds.
    record: what :meth:`step` returned for this step beside the new state.
    work: the pass's :class:`Workspace` from :meth:`init` (a fresh one if None).

* ``step(model, state, external, n, dt, work) -> (State, record)``: the step; raises
  :class:`~casadi_keyframe.state.SimulationError` if it fails.
* ``step_vjp(model, start, end, record, n, dt, cotangent, work) -> (State, g_external)``:
  the cotangent ``a_{n+1}`` of the end state pulled back through the step,
  ``((dS_n/ds_n)^T a_{n+1}, (dS_n/de_n)^T a_{n+1})``; eq. (5) adds ``dphi/ds_n``.
* ``step_jvp(model, start, end, record, n, dt, tangent, d_external, work) -> State``: the
  tangent of the end state, ``(dS_n/ds_n) tangent + (dS_n/de_n) d_external``.

Both derivative steps are exact for the scheme unless the method's name says otherwise
(``swapped_step_vjp``: the paper's approximation).  Pinned and attached components follow
prescribed motion that no control changes: the derivative steps drop their parts (zero in
what they return).  ``symbolic_step`` and ``step_parameters`` give the same step as a CasADi
function for the reverse-mode reference.
"""
from __future__ import annotations

import numpy as np

from ..models.base import Model


class Workspace:
    """One pass's scratch: the linear solver's plan for the model (analysed once per pass)
    and the last solution, a warm start for the next iterative solve.  Made by
    :meth:`Integrator.init` for each forward, backward or tangent pass and dropped after.

    ``keep``: the pass keeps its step records, so a step may keep in its record what the
    derivative passes reuse (set by :func:`~casadi_keyframe.simulate.simulate`).
    ``records``: in a backward pass, the forward pass's step records, so a backward step
    can reuse what a later step kept (set by :func:`~casadi_keyframe.simulate.backward`)."""

    def __init__(self, plan=None):
        self.plan = plan
        self.warm = None
        self.keep = False
        self.records = ()

    def factor(self, A, keep: bool = False):
        return self.plan.factor(A, keep)


class Integrator:
    """Base of the schemes: the shared contract (module docstring) and a default ``init``."""

    name = "integrator"
    requires: type = Model  # the model capability the scheme's steps use

    def check_model(self, model) -> None:
        """Refuse a model that does not declare the capability this scheme needs."""
        if not (isinstance(model, Model) and isinstance(model, self.requires)):
            raise TypeError(f"{self.name} steps models that declare {self.requires.__name__} "
                            f"(casadi_keyframe.models.base); {type(model).__name__} does not")

    def init(self, model) -> Workspace:
        """A fresh :class:`Workspace` for one pass over ``model``."""
        self.check_model(model)
        return Workspace()

    def carry(self, model, record):
        """What the step after ``record``'s takes from it beyond its end state (None:
        nothing): plain tuples, arrays and None, equal exactly when the next step decides
        the same.  A pass that starts mid-run (a multiple-shooting segment) is given it by
        :meth:`resume`."""
        return None

    def resume(self, work, carried) -> None:
        """Let the pass of ``work`` start as if its first step followed one that left
        ``carried`` (:meth:`carry`; None: the start of a run)."""

    def decides_per_step(self, model) -> bool:
        """Whether the scheme decides something per step from the state that its symbolic
        step takes as a parameter (:meth:`step_parameters`' ``record``)."""
        return False

    def release(self, trajectory) -> None:
        """Hand back what ``trajectory``'s records keep for derivative passes, once none is
        to come (nothing here; a scheme that keeps factorisations returns them)."""

    def step(self, model, state, external, n: int, dt: float, work: Workspace | None = None):
        raise NotImplementedError

    def step_vjp(self, model, start, end, record, n: int, dt: float, cotangent,
                 work: Workspace | None = None):
        raise NotImplementedError

    def step_jvp(self, model, start, end, record, n: int, dt: float, tangent, d_external,
                 work: Workspace | None = None):
        raise NotImplementedError

    @staticmethod
    def step_parameters(model, t: float, dt: float, record=None) -> np.ndarray:
        """The symbolic step's inputs S for the step from t: what depends on time, and what
        the numeric step decided (``record``: e.g. the contacts it held)."""
        raise NotImplementedError

    def symbolic_step(self, model):
        """``(X, V, E, dt, S) -> (X+, V+)`` as a CasADi Function on ``dim x n`` matrices."""
        raise NotImplementedError


def mass_diagonal(model) -> np.ndarray:
    """The diagonal of the mass matrix M over the flat ``particles * dim`` components."""
    return np.repeat(model.masses, model.dim)


def free_components(model, shape) -> np.ndarray:
    """The model's free-component mask as floats of ``shape`` (1 free, 0 constrained)."""
    return model.free_mask().astype(float).reshape(shape)
