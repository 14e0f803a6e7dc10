"""ControlProblem: a model, an integrator, controls and an objective over a horizon."""
from __future__ import annotations

import copy
from pathlib import Path

import casadi as ca
import numpy as np

from .controls import Controls, resample_steps
from .models.base import PhysicalReport
from .objectives import Objective
from .objectives.tolerances import PhysicalLimits
from .simulate import simulate
from .state import Trajectory
from .views import View, checked_view


class ControlProblem:
    """Find controls u minimising ``objective`` over ``steps`` steps of size ``dt``.

    ``x0, v0`` are ``(particles, dim)``; ``external`` is an optional stored force per step
    ``(steps, particles, dim)`` that is not optimised (the flock's wander, gravity).
    ``view`` says what pictures show beyond the model and keyframes (:mod:`.views`).
    ``guess`` is an optional starting point for the optimizer: flat controls, or a rule
    that makes them from a problem (a function of the problem), applied when first asked
    (:meth:`initial_controls`) and kept as :attr:`guess_rule`, so a problem made from this
    one (the frames after a kept one) can make its own.  ``source``
    is where the problem came from, when it was built from a problem file: an object whose
    ``build(**overrides)`` builds it again with more overrides
    (:class:`~casadi_keyframe.loading.ProblemSource`, see :meth:`at_resolution`).
    ``inputs`` are the files it was built from (a cloth's mesh, target meshes): a saved run
    records their content and is read back only while they are unchanged.  ``limits``
    (:class:`~casadi_keyframe.objectives.tolerances.PhysicalLimits`) say when the motion of
    a model that reports it (cloth) counts as physical: part of the goal (default limits).
    """

    def __init__(self, *, model, integrator, x0, v0, steps: int, dt: float,
                 controls: Controls, objective, external=None, name: str = "problem",
                 view: View | None = None, guess=None, source=None, scene=None, inputs=(),
                 limits: PhysicalLimits | None = None):
        if not (isinstance(steps, (int, np.integer)) and steps >= 1):
            raise ValueError(f"steps must be a positive integer, got {steps!r}")
        if not (np.isfinite(dt) and dt > 0):
            raise ValueError(f"dt must be positive and finite, got {dt!r}")
        self.model, self.integrator = model, integrator
        self.steps, self.dt, self.name = int(steps), float(dt), name
        shape = (model.n, model.dim)
        self.x0 = _state(x0, shape, "initial positions x0")
        self.v0 = _state(v0, shape, "initial velocities v0")
        if external is None:
            external = np.zeros((self.steps,) + shape)
        self.external = np.asarray(external, dtype=float)
        if self.external.shape != (self.steps,) + shape:
            raise ValueError(f"external forces must have shape {(self.steps,) + shape}, "
                             f"got {self.external.shape}")
        self.controls = copy.copy(controls)  # bound here: the caller's object stays as given
        self.controls.bind(model.n, model.dim, self.steps)
        objective = objective if isinstance(objective, Objective) else Objective(
            objective if isinstance(objective, (list, tuple)) else [objective])
        self.objective_terms = objective.bound(model, self.steps)
        if not self.objective_terms.state_terms:
            raise ValueError("the objective has no keyframe term: nothing to aim for")
        self._control_fn = self._compile_control_terms()
        self.view = checked_view(view, scene)
        self.guess_rule = guess if callable(guess) else None
        self._guess = (None if guess is None or self.guess_rule is not None
                       else self.controls.check(guess).copy())
        self.source = source
        self.inputs = tuple(Path(p).expanduser().resolve() for p in inputs)
        if limits is not None and not isinstance(limits, PhysicalLimits):
            raise ValueError(f"limits must be PhysicalLimits(stretch=..., depth=...), got "
                             f"{limits!r}")
        self.limits = (None if not isinstance(model, PhysicalReport) else
                       limits or PhysicalLimits())

    # -- the simulation ------------------------------------------------------------------
    @property
    def size(self) -> int:
        return self.controls.size

    @property
    def horizon(self) -> float:
        """Simulated time in seconds, ``steps * dt``."""
        return self.steps * self.dt

    def resampled(self, dt: float) -> "ControlProblem":
        """The same problem at time step ``dt``: the same horizon in ``horizon / dt`` steps,
        every keyframe at the same time, the stored external forces and the guess carried as
        force-versus-time (:func:`~casadi_keyframe.controls.resample_steps`), the controls
        rebound to the new step count.  Model, integrator, x0, v0 and view are shared; at
        the problem's own dt the problem itself is returned.

        Raises ValueError if ``dt`` does not divide the horizon into whole steps or a keyframe
        time falls between two steps of the new grid.
        """
        steps = self._steps_for(dt)
        if steps == self.steps:
            return self

        frames = sorted({t.frame for t in self.objective_terms.state_terms})

        def frame_of(term):
            if (term.frame * steps) % self.steps:
                raise ValueError(
                    f"{self.name}: keyframe {term.label} at t = {term.frame * self.dt:.6g} s "
                    f"falls between steps of dt = {self.horizon / steps:.6g} s (frame "
                    f"{term.frame * steps / self.steps:.6g}); choose a dt whose steps land on "
                    f"every keyframe (frames {frames} of {self.steps} at dt = {self.dt:.6g} s)")
            return term.frame * steps // self.steps

        objective = self.objective_terms.retimed(frame_of)
        guess = None if not self.has_guess else self.controls.resample(self._made_guess(),
                                                                        steps)
        return self._rebuilt(steps=steps, dt=self.horizon / steps, objective=objective,
                             external=resample_steps(self.external, steps), guess=guess)

    def at_resolution(self, **overrides) -> "ControlProblem":
        """This problem's file built again with ``overrides`` over the ones it was built with,
        e.g. ``rows=12, cols=12`` for a coarser mesh of the same cloth (``solve``'s
        ``resolutions``).  Only a problem as built from its file knows how: a problem changed
        since (``with_objective``, ``resampled``, ...) raises ValueError."""
        if self.source is None:
            raise ValueError(f"{self.name}: this problem was not built from a problem file, or "
                             "was changed since (with_objective, with_guess, resampled), so it "
                             "cannot be rebuilt at another resolution; build the coarser "
                             "problems yourself and pass them as resolutions")
        return self.source.build(**overrides)

    def with_source(self, source) -> "ControlProblem":
        """The same problem, everything shared, recorded as built from ``source``."""
        out = copy.copy(self)
        out.source = source
        return out

    def with_objective(self, objective) -> "ControlProblem":
        """The same problem (model, integrator, start, controls, view, guess shared) with
        another objective, e.g. a keyframe with a shifted target or a stiffer weight."""
        return self._rebuilt(objective=objective)

    def with_controls(self, controls: Controls) -> "ControlProblem":
        """The same problem with other controls (e.g. initial velocities instead of step
        forces); the guess is dropped (it was for the old controls)."""
        return self._rebuilt(controls=controls, guess=None)

    def with_guess(self, guess) -> "ControlProblem":
        """The same problem starting the optimizer from ``guess`` (flat controls), e.g.
        controls computed by simulating this problem."""
        return self._rebuilt(guess=guess)

    def _rebuilt(self, **changes) -> "ControlProblem":
        """A new problem from this one's arguments with ``changes``; the controls are an
        unbound copy for the (possibly new) step count."""
        steps = changes.pop("steps", self.steps)
        args = dict(model=self.model, integrator=self.integrator, x0=self.x0, v0=self.v0,
                    steps=steps, dt=self.dt, controls=self.controls.for_steps(steps),
                    objective=self.objective_terms, external=self.external, name=self.name,
                    view=self.view, inputs=self.inputs, limits=self.limits)
        if "guess" not in changes:  # made for this problem: the rule's guess, not the rule
            args["guess"] = self._made_guess()
        return ControlProblem(**{**args, **changes})

    def _steps_for(self, dt: float) -> int:
        """The whole number of steps of size ``dt`` in the horizon, or a ValueError."""
        if not (isinstance(dt, (int, float, np.floating, np.integer)) and np.isfinite(dt)
                and dt > 0):
            raise ValueError(f"{self.name}: a time step must be a positive number, got {dt!r}")
        n = self.horizon / dt
        steps = int(round(n))
        if steps < 1 or abs(n - steps) > 1e-6 * max(n, 1.0):
            raise ValueError(
                f"{self.name}: dt = {dt:.6g} s does not divide the horizon of {self.horizon:.6g} s "
                f"({self.steps} steps of {self.dt:.6g} s) into whole steps ({n:.6g}); choose "
                f"dt = horizon / k for a whole k, e.g. {self.dt:.6g} s times a divisor of "
                f"{self.steps}")
        return steps

    def initial_controls(self) -> np.ndarray:
        """Where the optimizer starts: the problem's ``guess`` if it has one, else the passive
        simulation's controls (zeros); a flat float64 vector."""
        return self.controls.zeros() if not self.has_guess else self._made_guess().copy()

    def _made_guess(self):
        """The guess (made by its rule the first time), or None."""
        if self._guess is None and self.guess_rule is not None:
            self._guess = self.controls.check(self.guess_rule(self)).copy()
        return self._guess

    @property
    def has_guess(self) -> bool:
        """Whether the optimizer starts from a given guess rather than the passive controls."""
        return self._guess is not None or self.guess_rule is not None

    def bounds(self):
        return self.controls.bounds()

    def simulate(self, u=None, *, records: bool = True) -> Trajectory:
        """Simulate with controls ``u`` (default: passive); raises SimulationError on blow-up.

        ``records=False`` is for values only: the run keeps nothing for a backward pass,
        which on a large flock is most of the memory.
        """
        u = self.controls.zeros() if u is None else self.controls.check(u)
        return simulate(self.integrator, self.model, self.x0, *self._start_and_forces(u),
                        self.dt, records=records)

    def _start_and_forces(self, u):
        """``(v0, external)`` under controls u: the start velocities and every step's force."""
        offset = self.controls.velocity_offset(u)
        ext = self.controls.external(u)
        return (self.v0 if offset is None else self.v0 + offset,
                self.external if ext is None else self.external + ext)

    # -- the objective -------------------------------------------------------------------
    def state_cost(self, traj: Trajectory, *, gradient: bool = True):
        """Keyframe cost of a trajectory and its derivative per frame, ``(value, gx, gv)``;
        with ``gradient=False`` the value only (``gx, gv`` None)."""
        terms = self.objective_terms.state_terms + self.objective_terms.trajectory_terms
        if not gradient:
            return float(sum(t.value(traj) for t in terms)), None, None
        gx = np.zeros_like(traj.x)
        gv = np.zeros_like(traj.v)
        value = sum(t.accumulate(traj, gx, gv) for t in terms)
        return float(value), gx, gv

    def control_cost(self, u):
        """Value and gradient of the control terms (smoothness)."""
        val, grad = self._control_fn(self.controls.check(u))
        return float(val), np.asarray(grad).ravel()

    def objective(self, u) -> float:
        """The objective at the controls ``u`` (a flat vector of :attr:`size` real numbers;
        anything else is refused with what it should be)."""
        u = self.controls.check(u)
        traj = self.simulate(u, records=False)
        return self.state_cost(traj, gradient=False)[0] + self.control_cost(u)[0]

    def objective_and_gradient(self, u, gradient=None):
        """``(phi, dphi/du)`` by the named route ("adjoint", "swapped", "casadi" or "fd", see
        :mod:`casadi_keyframe.adjoints`; None: the registry's default) or a route object."""
        from .adjoints import get_gradient
        return get_gradient(gradient)(self, self.controls.check(u))

    def directional_derivative(self, u, du) -> float:
        """``dphi/du . du`` by one tangent-linear pass (the integrator's exact ``step_jvp``
        carried through the simulation), no backward pass."""
        u, du = self.controls.check(u), self.controls.check(du)
        v0, ext = self._start_and_forces(u)
        d_offset, d_ext = self.controls.velocity_offset(du), self.controls.external(du)
        tangent = (np.zeros_like(self.x0),
                   np.zeros_like(self.v0) if d_offset is None else d_offset,
                   np.zeros_like(ext) if d_ext is None else d_ext)
        traj, dx, dv = simulate(self.integrator, self.model, self.x0, v0, ext, self.dt,
                                records=False, tangent=tangent)
        _, gx, gv = self.state_cost(traj)
        return float(np.vdot(gx, dx) + np.vdot(gv, dv) + self.control_cost(u)[1] @ du)

    def breakdown(self, u, traj: Trajectory | None = None) -> dict:
        """Objective split into keyframe error and control cost, plus per-term misses,
        for a model that reports it (cloth) whether the motion stays physical
        (``physical``: largest spring stretch, deepest penetration of a collider), and for
        force controls their :meth:`effort`."""
        u = self.controls.check(u)
        traj = self.simulate(u, records=False) if traj is None else traj
        keyframe = self.state_cost(traj, gradient=False)[0]
        control = self.control_cost(u)[0]
        out = {"objective": keyframe + control, "keyframe_error": keyframe,
               "control_cost": control, "control_norm": float(np.linalg.norm(u)),
               "misses": [t.miss(traj) for t in self.objective_terms.state_terms]}
        if isinstance(self.model, PhysicalReport):
            out["physical"] = self.model.physical_report(traj.x, traj.dt)
        effort = self.effort(u)
        if effort is not None:
            out["effort"] = effort
        return out

    def effort(self, u) -> dict | None:
        """The control forces as the accelerations they give the particles they push (m/s^2,
        force over mass): ``rms_acceleration`` over the controlled particles and steps and
        ``peak_acceleration``, what an animator judges a motion's effort by; None for
        controls that are not forces (initial velocities)."""
        forces = self.controls.external(self.controls.check(u))
        if forces is None:
            return None
        idx = self.controls.idx
        acc = np.linalg.norm(forces[:, idx], axis=-1) / self.model.masses[idx]
        return {"rms_acceleration": float(np.sqrt(np.mean(acc ** 2))),
                "peak_acceleration": float(acc.max())}

    def physical_shortfall(self, traj: Trajectory) -> list[str]:
        """What ``traj`` breaks of the problem's :attr:`limits` (torn, sunk), one phrase each;
        empty for a model without limits."""
        if self.limits is None:
            return []
        return self.limits.shortfall(self.model.physical_report(traj.x, traj.dt))

    # -- the control terms, compiled -------------------------------------------------------
    def control_expression(self, U) -> ca.MX:
        """The control terms' value as a CasADi expression of the controls ``U`` (MX)."""
        val = 0
        for term in self.objective_terms.control_terms:
            val += term.symbolic(U, self.controls, self.dt)
        return ca.MX(val) if not isinstance(val, ca.MX) else val

    def _compile_control_terms(self) -> ca.Function:
        U = ca.MX.sym("U", self.size)
        val = self.control_expression(U)
        return ca.Function("control_cost", [U], [val, ca.gradient(val, U)])


def _state(value, shape, what) -> np.ndarray:
    arr = np.asarray(value, dtype=float)
    if arr.shape != shape:
        raise ValueError(f"{what} must have shape {shape} (particles, dim), got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{what} contain NaN or inf")
    return arr.copy()
