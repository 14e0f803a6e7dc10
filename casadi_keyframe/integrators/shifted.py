"""A scheme whose step ``n`` is another's step ``first + n``: a run that starts at frame
``first`` (a multiple-shooting segment, a shot re-solved from a frame) driven by the public
loops, which count from 0, so forces, colliders and attachments see the right time.

``carried`` is what the step before ``first`` left to the next (the scheme's ``carry``:
held contacts released, springs kept taut): a run started from it decides as the whole run
did.  The symbolic step's parameters are asked at ``t + first dt`` (the CasADi route).
"""
from __future__ import annotations


class Shifted:
    """``integrator`` with every step number moved on by ``first``, its first step
    following one that left ``carried`` (None: as at the start of a run)."""

    def __init__(self, integrator, first: int, carried=None):
        self.integrator, self.first, self.carried = integrator, int(first), carried
        self.name = integrator.name

    def init(self, model):
        work = self.integrator.init(model)
        self.integrator.resume(work, self.carried)
        return work

    def carry(self, model, record):
        return self.integrator.carry(model, record)

    def resume(self, work, carried) -> None:
        self.integrator.resume(work, carried)

    def release(self, trajectory) -> None:
        self.integrator.release(trajectory)

    def decides_per_step(self, model) -> bool:
        return self.integrator.decides_per_step(model)

    def symbolic_step(self, model):
        return self.integrator.symbolic_step(model)

    def step_parameters(self, model, t: float, dt: float, record=None):
        return self.integrator.step_parameters(model, t + self.first * dt, dt, record)

    def step(self, model, state, external, n, dt, work=None):
        return self.integrator.step(model, state, external, n + self.first, dt, work)

    def step_vjp(self, model, start, end, record, n, dt, cotangent, work=None):
        return self.integrator.step_vjp(model, start, end, record, n + self.first, dt,
                                        cotangent, work)

    def step_jvp(self, model, start, end, record, n, dt, tangent, d_external, work=None):
        return self.integrator.step_jvp(model, start, end, record, n + self.first, dt,
                                        tangent, d_external, work)

    def force_for(self, model, x, v, v1, n: int, dt: float, work=None):
        return self.integrator.force_for(model, x, v, v1, n + self.first, dt, work)

    @property
    def swapped_step_vjp(self):
        """The wrapped scheme's swapped backward step, shifted (None if it has none)."""
        swapped = getattr(self.integrator, "swapped_step_vjp", None)
        if swapped is None:
            return None
        return lambda model, start, end, record, n, dt, cotangent, work=None: swapped(
            model, start, end, record, n + self.first, dt, cotangent, work)
