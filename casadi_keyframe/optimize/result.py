"""What a search returns: :class:`Result`, in scipy's ``OptimizeResult`` vocabulary, and
the records it carries, :class:`Stage`, :class:`Timings` and :class:`HistoryRecord`.

Every producer (:func:`~.search.solve`, :func:`~.augmented_lagrangian.solve_augmented`,
:func:`~.constrained.lower_effort`) writes its history with :func:`history_record`, its
stages with :func:`stage_record` and builds its result with :func:`assemble`, so
``summary.json``, ``result.npz``, the convergence plot, a sweep's table and a checkpoint
read the same keys whoever made the result.  The records are ``TypedDict``\\ s, plain
dicts: they go to JSON as they are.  A :class:`Result` checks them when it is made, so a
producer that leaves out a key (a history without ``objective`` would draw an empty
convergence plot) fails at once, by name.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TypedDict

import numpy as np

from ..state import Trajectory
from .deadline import now
from .outcome import CONVERGED, STATUS


class _HistoryFields(TypedDict):
    iteration: int
    """1, 2, ... over the whole call (all stages and rounds)."""
    stage: int
    """The stage it belongs to (0 without stages)."""
    dt: float
    """That stage's time step (s)."""
    particles: int
    """That stage's particle count."""
    objective: float
    """The objective at the point, on its stage's true targets, dt and mesh."""
    keyframe_error: float
    """Its state terms' part (the objective less the control cost)."""
    control_norm: float
    """The Euclidean norm of the controls."""
    seconds: float
    """Wall time since the call began."""
    nfev: int
    """Evaluations so far in that stage."""


class HistoryRecord(_HistoryFields, total=False):
    """One iteration of a search: the best point so far, made by :func:`history_record`;
    a producer may add the optional keys below."""

    round: int
    """The round of hard keyframes or of multiple shooting."""
    defect: float
    """Multiple shooting's largest rms defect, in tolerances (1: as large as it)."""
    control_cost: float
    """:func:`~.constrained.lower_effort`'s control cost."""
    damping: float
    """:func:`~.constrained.lower_effort`'s damping."""
    misses: list
    """:func:`~.constrained.lower_effort`'s ``(kind, rms miss)`` per keyframe row."""
    gradient_growth: float
    """The backward growth of the gradient at the point (:mod:`casadi_keyframe.health`)."""


class Timings(TypedDict):
    """Where a call's time went, and the evaluations it stepped back from.

    * ``wall_seconds``: the whole call, wall clock;
    * ``evaluation_seconds``: inside objective and gradient evaluations (simulations and
      backward passes);
    * ``failed_simulations``: evaluations whose simulation failed (blew up, NaN) and that
      the search stepped back from (a count, kept beside the time);
    * ``stage_seconds``: wall seconds of each stage, in order.
    """

    wall_seconds: float
    evaluation_seconds: float
    failed_simulations: int
    stage_seconds: list


class _StageFields(TypedDict):
    stage: int
    """Its number, 0 first, one per record."""
    dt: float
    """Its problem's time step (s)."""
    steps: int
    """Its problem's steps."""
    particles: int
    """Its problem's particles."""
    nit: int
    """Its iterations."""
    nfev: int
    """Its evaluations."""
    njev: int
    """Its gradients."""
    fun: float
    """The best objective it reached, on its true targets, at its own dt and mesh."""
    start_objective: float | None
    """The objective at the controls it started from (None if not evaluated)."""
    start_keyframe_error: float | None
    """Its state terms' part there."""
    success: bool
    """``status == 0``."""
    status: int
    """How it ended (as :attr:`Result.status`)."""
    message: str
    """That in a sentence."""
    seconds: float
    """Its wall time."""
    evaluation_seconds: float
    """Its time inside evaluations."""
    failed_simulations: int
    """Its evaluations that failed (refused gradients included)."""


class Stage(_StageFields, total=False):
    """One stage of a call: a continuation time step, a coarser mesh, a homotopy level, a
    multiple-shooting stage, a round of hard keyframes, or the kept point returned; a
    producer adds the optional keys below."""

    weight_scale: float
    """A round's keyframe weights' factor."""
    segments: int
    """A multiple-shooting stage's segments."""
    defect: float
    """Its largest rms defect left, in tolerances."""
    control_cost: float
    """A round's control cost at its controls."""
    misses: list
    """A round's keyframe misses at its controls, as in ``breakdown``."""
    gradient_growth: float
    """The largest backward growth of its evaluations (a route that watches it)."""
    gradient_refused: int
    """Its evaluations whose gradient was refused (in ``failed_simulations`` too)."""


@dataclass
class Result:
    """The outcome of a search: the best controls it saw, and how it got there, in scipy's
    ``OptimizeResult`` names where scipy has one.  Made by :func:`assemble`, which checks
    the records (ValueError naming a missing key)."""

    x: np.ndarray
    """The controls, a flat vector on the problem's own grid and mesh."""
    fun: float
    """The objective at ``x``."""
    jac: np.ndarray
    """Its gradient at ``x`` by the :attr:`route` (NaN if an interrupt stopped it)."""
    nit: int
    """Iterations, over all stages and rounds."""
    nfev: int
    """Objective evaluations (each one simulation), failed ones included."""
    njev: int
    """Gradients computed: one per evaluation that did not fail."""
    success: bool
    """``status == 0``."""
    status: int
    """0 converged (the goal met); 1 a limit reached first; 2 the search failed; 3
    interrupted."""
    message: str
    """How it ended in a sentence and, short of the goal, what it misses."""
    method: str
    """The search method that ran (a :data:`~.methods.METHODS` name or ``lower_effort``)."""
    route: object
    """The gradient route that ran (a :class:`~casadi_keyframe.adjoints.Route`)."""
    trajectory: Trajectory
    """The simulation at ``x``."""
    history: list[HistoryRecord]
    """One :class:`HistoryRecord` per iteration."""
    timings: Timings
    """Where the time went (:class:`Timings`)."""
    breakdown: dict
    """The objective at ``x`` term by term, misses and physical report included
    (:meth:`~casadi_keyframe.problem.ControlProblem.breakdown`)."""
    stages: list[Stage]
    """One :class:`Stage` per stage or round."""

    def __post_init__(self):
        if self.status not in STATUS or self.success != (self.status == CONVERGED):
            raise ValueError(f"Result status must be one of {sorted(STATUS)} and success "
                             f"status == {CONVERGED}, got status {self.status!r}, success "
                             f"{self.success!r}")
        _check_keys("timings", self.timings, Timings)
        for i, record in enumerate(self.history):
            _check_keys(f"history record {i}", record, HistoryRecord)
        for i, stage in enumerate(self.stages):
            _check_keys(f"stage {i}", stage, Stage)

    @property
    def gradient(self) -> str:
        """The name of the gradient route that ran."""
        return self.route.name

    @property
    def start(self) -> dict:
        """Objective and keyframe error at the starting controls (of the first stage)."""
        first = self.stages[0] if self.stages else {}
        return {"objective": first.get("start_objective"),
                "keyframe_error": first.get("start_keyframe_error")}

    def summary(self) -> dict:
        """JSON-ready summary (no arrays): the scalar fields, ``status_name``, ``timings``,
        ``breakdown``, ``stages``, the gradient's norm and its health over the search
        (``gradient_health``: the largest backward growth and the refused evaluations)."""
        return {"fun": self.fun, "nit": self.nit, "nfev": self.nfev, "njev": self.njev,
                "success": self.success, "status": self.status,
                "status_name": STATUS[self.status], "message": self.message,
                "method": self.method, "gradient": self.gradient, "timings": self.timings,
                "breakdown": self.breakdown, "stages": self.stages,
                "gradient_norm": float(np.linalg.norm(self.jac)),
                "gradient_health": _health(self.stages, self.route)}


def _health(stages, route) -> dict:
    """The gradients' health over ``stages``: the largest backward growth (None if no stage
    watched one), the bound ``route`` is held to (None: refused only when not finite) and
    the evaluations refused."""
    bound = route.bound
    growth = [s["gradient_growth"] for s in stages if "gradient_growth" in s]
    return {"largest_growth": max(growth) if growth else None,
            "bound": bound if math.isfinite(bound) else None,
            "refused": sum(s.get("gradient_refused", 0) for s in stages)}


def _check_keys(what: str, record, kind) -> None:
    """Refuse a ``record`` of ``kind`` (a TypedDict) that lacks a required key or carries a
    key it does not declare; ``what`` names it in the message."""
    missing = sorted(kind.__required_keys__ - set(record))
    extra = sorted(set(record) - kind.__required_keys__ - kind.__optional_keys__)
    problems = ([f"lacks {', '.join(missing)}"] if missing else []) + (
        [f"has undeclared {', '.join(extra)}"] if extra else [])
    if problems:
        raise ValueError(f"Result {what} {' and '.join(problems)}: {kind.__name__} lists "
                         f"the keys; make records with the helpers of {__name__}")


def history_record(problem, u, *, objective: float, keyframe_error: float, iteration: int,
                   stage: int, seconds: float, nfev: int, **extra) -> HistoryRecord:
    """The :class:`HistoryRecord` of an iteration of ``problem`` that reached the controls
    ``u`` with this ``objective`` and ``keyframe_error``; ``extra`` are the optional keys
    :class:`HistoryRecord` names."""
    record = {"iteration": iteration, "stage": stage, "dt": problem.dt,
              "particles": problem.model.n, "objective": float(objective),
              "keyframe_error": float(keyframe_error),
              "control_norm": float(np.linalg.norm(u)), "seconds": seconds, "nfev": nfev,
              **extra}
    _check_keys("history record", record, HistoryRecord)
    return record


def stage_record(problem, stage: int, *, nit: int, nfev: int, njev: int, fun: float,
                 status: int, message: str, seconds: float, evaluation_seconds: float,
                 failed_simulations: int, start=(None, None), **extra) -> Stage:
    """The :class:`Stage` of stage number ``stage``, run on ``problem``, that ended with
    ``status`` and ``message``; ``start`` is ``(objective, keyframe error)`` at its starting
    controls (None if not evaluated); ``extra`` are the optional keys :class:`Stage` names."""
    record = {"stage": stage, "dt": problem.dt, "steps": problem.steps,
              "particles": problem.model.n, "nit": nit, "nfev": nfev, "njev": njev,
              "fun": float(fun), "start_objective": start[0], "start_keyframe_error": start[1],
              "success": status == CONVERGED, "status": status, "message": message,
              "seconds": seconds, "evaluation_seconds": evaluation_seconds,
              "failed_simulations": failed_simulations, **extra}
    _check_keys("stage", record, Stage)
    return record


def assemble(problem, u, *, fun: float, jac, status: int, message: str, method: str,
             route, stages: list, history: list, started: float,
             trajectory: Trajectory | None = None) -> Result:
    """The :class:`Result` of a call on ``problem`` that ended at the controls ``u``:
    ``nit``, ``nfev``, ``njev`` and :class:`Timings` totalled over ``stages``, ``success``
    from ``status``, the wall time since ``started`` (:func:`~.deadline.now`), and the
    ``trajectory`` at ``u`` (simulated unless given) with the problem's breakdown there."""
    traj = problem.simulate(u) if trajectory is None else trajectory
    timings = {"wall_seconds": now() - started,
               "evaluation_seconds": sum(s["evaluation_seconds"] for s in stages),
               "failed_simulations": sum(s["failed_simulations"] for s in stages),
               "stage_seconds": [s["seconds"] for s in stages]}
    return Result(x=u, fun=float(fun), jac=jac, nit=sum(s["nit"] for s in stages),
                  nfev=sum(s["nfev"] for s in stages), njev=sum(s["njev"] for s in stages),
                  success=status == CONVERGED, status=status, message=message,
                  method=method, route=route, trajectory=traj, history=history,
                  timings=timings, breakdown=problem.breakdown(u, traj), stages=stages)
