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

import time
from dataclasses import dataclass
from typing import TypedDict

import numpy as np

from ..state import Trajectory
from .outcome import CONVERGED, STATUS


class _HistoryFields(TypedDict):
    iteration: int
    stage: int
    dt: float
    particles: int
    objective: float
    keyframe_error: float
    control_norm: float
    seconds: float
    nfev: int


class HistoryRecord(_HistoryFields, total=False):
    """One iteration of a search (the point it reached), made by :func:`history_record`.

    Every record has:

    * ``iteration``: 1, 2, ... over the whole call (all stages and rounds);
    * ``stage``: the stage it belongs to (0 without continuation or coarser meshes);
    * ``dt``, ``particles``: that stage's time step (s) and particle count;
    * ``objective``: the objective at the point, at that stage's dt and mesh;
    * ``keyframe_error``: its state terms' part (the objective less the control cost);
    * ``control_norm``: the Euclidean norm of the controls;
    * ``seconds``: wall time since the call began;
    * ``nfev``: evaluations so far in that stage.

    Producers may add:

    * ``round``: the augmented-Lagrangian round (:func:`~.augmented_lagrangian.solve_augmented`,
      and multiple shooting's rounds);
    * ``defect``: multiple shooting's largest rms defect between segments, in units of the
      keyframes' tolerances (1: as large as the tolerance);
    * ``control_cost``, ``damping``, ``misses``: :func:`~.constrained.lower_effort`'s
      control cost, the damping it stepped with, and each keyframe row's ``(kind, rms
      miss)``;
    * ``gradient_growth``: the backward growth of the gradient at the point
      (:mod:`casadi_keyframe.health`; routes that watch their backward pass).
    """

    round: int
    defect: float
    control_cost: float
    damping: float
    misses: list
    gradient_growth: float


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
    dt: float
    steps: int
    particles: int
    nit: int
    nfev: int
    njev: int
    fun: float
    start_objective: float | None
    start_keyframe_error: float | None
    success: bool
    status: int
    message: str
    seconds: float
    evaluation_seconds: float
    failed_simulations: int


class Stage(_StageFields, total=False):
    """One stage of a call: a continuation time step, a coarser mesh, an
    augmented-Lagrangian round, or :func:`~.constrained.lower_effort`'s one run.

    Every stage has:

    * ``stage``: its number, 0 first;
    * ``dt``, ``steps``, ``particles``: its problem's time step (s), steps and particles;
    * ``nit``, ``nfev``, ``njev``: its iterations, evaluations and gradients (as
      :class:`Result`'s);
    * ``fun``: the best objective it reached, at its own dt and mesh;
    * ``start_objective``, ``start_keyframe_error``: the objective and its state terms'
      part at the controls it started from (None if not evaluated);
    * ``success``, ``status``, ``message``: how it ended (as :class:`Result`'s);
    * ``seconds``, ``evaluation_seconds``, ``failed_simulations``: as in :class:`Timings`,
      for this stage.

    An augmented-Lagrangian round adds ``weight_scale`` (its keyframe weights' factor),
    ``control_cost`` and ``misses`` (the problem's keyframe misses at its controls, as
    in ``breakdown``).  A multiple-shooting stage adds ``segments`` and ``defect`` (the
    largest rms defect left, in tolerances); its ``fun`` is the objective on the stitched
    segments.  A search's stage adds its gradients' health
    (:class:`~casadi_keyframe.health.GrowthLog`): ``gradient_growth``, the largest backward
    growth of its evaluations (a route that watches its backward pass), and
    ``gradient_refused``, the evaluations whose gradient was refused (counted in
    ``failed_simulations`` too).
    """

    weight_scale: float
    segments: int
    defect: float
    control_cost: float
    misses: list
    gradient_growth: float
    gradient_refused: int


@dataclass
class Result:
    """The outcome of a search: the best controls it saw, and how it got there.

    Fields (scipy's ``OptimizeResult`` names where scipy has one):

    * ``x``: the controls, a flat vector on the problem's own grid and mesh;
    * ``fun``: the objective at ``x``;
    * ``jac``: its gradient at ``x`` by the route ``gradient`` names (NaN if an interrupt
      stopped that evaluation);
    * ``nit``: iterations, over all stages and rounds;
    * ``nfev``: objective evaluations (each one simulation), failed ones included;
    * ``njev``: gradients the search computed: one per evaluation that did not fail
      (:func:`~.constrained.lower_effort`: its adjoint sweeps, one per keyframe residual
      row and iteration);
    * ``success``: ``status == 0``;
    * ``status``: how the search ended: 0 converged; 1 a limit (iterations, evaluations,
      ``time_limit``) was reached first; 2 the search failed (a line search found no lower
      point, an IPOPT error); 3 interrupted (Ctrl-C, SIGTERM);
    * ``message``: that in a sentence and, on failure, what to try;
    * ``method``: ``"lbfgsb"``, ``"ipopt"`` or ``"lower_effort"``;
    * ``gradient``: the gradient route that ran (``"adjoint"``, ``"swapped"``, ...);
    * ``trajectory``: the simulation at ``x``;
    * ``history``: one :class:`HistoryRecord` per iteration;
    * ``timings``: :class:`Timings`;
    * ``breakdown``: the problem's objective at ``x`` term by term, keyframe misses
      included (:meth:`~casadi_keyframe.problem.ControlProblem.breakdown`);
    * ``stages``: one :class:`Stage` per stage or round.

    Made by :func:`assemble`; the records are checked here (ValueError naming the missing
    keys).
    """

    x: np.ndarray
    fun: float
    jac: np.ndarray
    nit: int
    nfev: int
    njev: int
    success: bool
    status: int
    message: str
    method: str
    gradient: str
    trajectory: Trajectory
    history: list[HistoryRecord]
    timings: Timings
    breakdown: dict
    stages: list[Stage]

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
                "gradient_health": _health(self.stages, self.gradient)}


def _health(stages, route: str) -> dict:
    """The gradients' health over ``stages``: the largest backward growth (None if no stage
    watched one), the bound the route named ``route`` is held to (None: refused only when
    not finite, or a strategy of the user's own) and the evaluations refused."""
    from ..adjoints import GRADIENTS

    bound = getattr(GRADIENTS.get(route), "bound", math.inf)
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
             gradient: str, stages: list, history: list, started: float,
             trajectory: Trajectory | None = None) -> Result:
    """The :class:`Result` of a call on ``problem`` that ended at the controls ``u``:
    ``nit``, ``nfev``, ``njev`` and :class:`Timings` totalled over ``stages``, ``success``
    from ``status``, the wall time since ``started`` (``time.perf_counter()``), and the
    ``trajectory`` at ``u`` (simulated unless given) with the problem's breakdown there."""
    traj = problem.simulate(u) if trajectory is None else trajectory
    timings = {"wall_seconds": time.perf_counter() - started,
               "evaluation_seconds": sum(s["evaluation_seconds"] for s in stages),
               "failed_simulations": sum(s["failed_simulations"] for s in stages),
               "stage_seconds": [s["seconds"] for s in stages]}
    return Result(x=u, fun=float(fun), jac=jac, nit=sum(s["nit"] for s in stages),
                  nfev=sum(s["nfev"] for s in stages), njev=sum(s["njev"] for s in stages),
                  success=status == CONVERGED, status=status, message=message,
                  method=method, gradient=gradient, trajectory=traj, history=history,
                  timings=timings, breakdown=problem.breakdown(u, traj), stages=stages)
