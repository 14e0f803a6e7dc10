"""The "adjoint" route: exact, the discrete adjoint of the scheme simulated, eq. (5) with the
integrator's hand-written backward step (symplectic Euler's eq. 8; the exact adjoint of
linearized backward Euler; full backward Euler's adjoint); about one forward pass.

Its backward pass is watched but held to no growth bound: it is the derivative of the
simulated map however sensitive that map is, and the route a refusal sends users to, so it
is refused only when not finite; its growth is on record (history, ``summary.json``,
``gradcheck``).  A growth is a ratio to what the objective fed in: at a start that already
hits its keyframes to round-off, large guessed forces make it enormous while the gradient
itself is tiny."""
from __future__ import annotations

from ..health import BackwardWatch, check_finite
from ..simulate import backward
from .base import Evaluation, Route, bare


class Adjoint(Route):
    """Exact: the discrete adjoint of the simulated scheme, by its hand-written backward step.

    ``guard`` (default): the evaluation fails with a GradientError if the backward pass
    grows past ``bound`` (default: the route's) or overflows; without, its growth is only
    recorded (the evaluation's ``growth``)."""

    name = "adjoint"
    exact = True
    help = "the exact hand adjoint"
    guard = True  # class default (subclasses may skip __init__)

    def __init__(self, *, guard: bool = True, bound: float | None = None):
        self.guard = guard
        if bound is not None:
            self.bound = bound

    def backward_step(self, integrator):
        """The integrator's backward step this strategy runs in eq. (5)."""
        return integrator.step_vjp

    def evaluate(self, problem, u) -> Evaluation:
        step_vjp = self.backward_step(problem.integrator)
        traj = problem.simulate(u)
        value, gx, gv = problem.state_cost(traj)
        watch = BackwardWatch(self, problem, guard=self.guard, bound=self.bound)
        try:
            g_ext, g0 = backward(problem.integrator, problem.model, traj, gx, gv,
                                 step_vjp=step_vjp, watch=watch)
        finally:
            problem.integrator.release(traj)
        c_val, c_grad = problem.control_cost(u)
        grad = problem.controls.pullback(g_ext, g0.v) + c_grad
        if self.guard:
            check_finite(self, grad, problem)
        return Evaluation(value + c_val, grad, bare(traj), watch.result())

    def likely_cause(self, model) -> str:
        return ("the motion itself is this sensitive (a long horizon through many contact "
                "switches, springs collapsed to almost no length, a simulation near blowing "
                "up): the exact gradient's linear model holds only for tiny steps. Fix: "
                "shorten the horizon or the window optimized, start from a better guess, or "
                "reduce the forces")

    def unguarded(self) -> "Adjoint":
        return type(self)(guard=False, bound=self.bound)
