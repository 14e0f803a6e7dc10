"""Step-size rules: what size of a descent's step (:mod:`.descents`) a residual search tries
next, and what it learns from a trial.

* :class:`TrustRadius`: the classical trust region (the Gauss-Newton method's): a trial is
  taken when it earns a share of the decrease the model predicted; the radius follows how
  well the model did;
* :class:`Halving`: backtracking, the whole step and then halved (the finish's landing);
* :class:`Damping`: a damping that grows on a refused trial and shrinks on a taken one (the
  finish's effort steps).
"""
from __future__ import annotations

SHRINK, GROW = 0.25, 2.0  # the radius after a poor step (times its length) and a good one


class TrustRadius:
    """A trust radius (``size``; None: unbounded while full steps do well) and the least
    ratio of actual to predicted decrease, ``accept``, that takes a step."""

    def __init__(self, radius: float | None, accept: float):
        self.size, self.accept = radius, accept

    def judge(self, ratio: float, length: float) -> bool:
        """After a trial of ``length`` whose actual decrease was ``ratio`` times the
        predicted one: the new radius, and whether the trial is taken."""
        self.size = _new_radius(self.size, ratio, length)
        return ratio > self.accept


def _new_radius(radius, ratio, length):
    """The trust radius after a step of ``length`` whose actual decrease was ``ratio`` times
    the predicted one (None: unbounded while full steps do well)."""
    if ratio < 0.25:
        return SHRINK * length
    if ratio > 0.75 and (radius is None or length >= 0.99 * radius):
        return None if radius is None else GROW * radius
    return length if radius is None else radius


class Halving:
    """The whole step, then halved, at most ``tries`` sizes in all."""

    def __init__(self, tries: int):
        self.tries = tries

    def sizes(self):
        return (0.5 ** k for k in range(self.tries))


class Damping:
    """A step damped by ``damping`` (the step is ``d / (1 + damping)``), tried at most
    ``tries`` times per iteration: a refused trial makes the damping ``4 damping + 1``, a
    taken one divides it by 3."""

    def __init__(self, damping: float, tries: int):
        self.damping, self.tries = damping, tries

    def sizes(self):
        for _ in range(self.tries):
            yield self.damping

    def taken(self) -> None:
        self.damping /= 3.0

    def refused(self) -> None:
        self.damping = 4.0 * self.damping + 1.0
