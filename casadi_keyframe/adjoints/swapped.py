"""The "swapped" route: APPROXIMATE, the paper's integrator-swapping adjoint of linearized
backward Euler (eqs. 13-15); about one forward pass, the same matrix transposed.  It is held
to a growth bound and known not to apply to some models (:meth:`Swapped.limits`)."""
from __future__ import annotations

from ..health import GROWTH_BOUND, warn_route_limits
from ..models.contact.penalty import BodyPenalty, SelfPenalty
from .adjoint import Adjoint


class Swapped(Adjoint):
    """APPROXIMATE: the paper's integrator-swapping adjoint (eqs. 13-15), the adjoint of full
    backward Euler run on a linearized backward Euler trajectory; its error is measured
    against "adjoint" or "casadi" in the gradient-accuracy study.  Its backward pass is
    refused past :data:`~casadi_keyframe.health.GROWTH_BOUND`: there it has left the exact
    adjoint behind (it diverges near curved colliders)."""

    name = "swapped"
    exact = False
    bound = GROWTH_BOUND
    help = "the paper's approximate one (cloth)"

    def backward_step(self, integrator):
        step = getattr(integrator, "swapped_step_vjp", None)
        if step is None:
            raise ValueError(
                f"gradient='swapped' is the paper's approximate adjoint of linearized backward "
                f"Euler (cloth); {integrator.name} has none: use gradient='adjoint', its "
                "exact adjoint")
        return step

    def evaluate(self, problem, u):
        warn_route_limits(self, problem.model)  # once per model
        return super().evaluate(problem, u)

    def limits(self, model) -> list[str]:
        """Penalty springs on curved bodies (sphere, capsule), whose curvature and damping
        terms make its backward pass grow without bound, self-contact, and friction, whose
        sliding impulses' derivatives it leaves out."""
        families = getattr(model, "families", ())
        curved = sorted({f.body.kind for f in families
                         if isinstance(f, BodyPenalty) and f.body.kind != "plane"})
        out = []
        if curved:
            out.append(f"penalty contact on curved bodies ({', '.join(curved)}s) can make it "
                       "overflow")
        if any(isinstance(f, SelfPenalty) for f in families):
            out.append("self-contact makes it inaccurate")
        if any(getattr(f, "stick_slide", None) is not None for f in families):
            out.append("with friction it is not the forward pass's derivative (it leaves out "
                       "the sliding impulses' derivatives)")
        return out

    def unreliable(self, limits: list[str]) -> str:
        return (f"{super().unreliable(limits)} (see 'casadi-keyframe study swap-validity'); "
                "the evaluation fails if its backward pass overflows. Use gradient='adjoint' "
                "(exact, same cost)")

    def likely_cause(self, model) -> str:
        limits = self.limits(model)
        where = ("; here: " + "; ".join(limits)) if limits else ""
        return ("the paper's swapped adjoint updates with the full force Jacobian, whose "
                "destabilising parts (contact curvature and contact damping on curved "
                "bodies, compressed springs) its backward recurrence amplifies every step"
                f"{where}. Fix: use --gradient adjoint (gradient='adjoint', exact, same cost); "
                "a reduced dt does not help (the growth compounds per step)")
