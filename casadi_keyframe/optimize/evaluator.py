"""The objective as every search method sees it: :class:`Evaluator` (memoised, keeping the
best point, counting failed simulations, writing the history and the checkpoint) of what
it is given to evaluate (:class:`RouteMerit`, a problem's objective by a gradient route, or
multiple shooting's merit of stacked variables), and :class:`MetricView`, the same
evaluator in a smooth metric's variables.  A merit returns an
:class:`~casadi_keyframe.adjoints.Evaluation` whole (value, gradient, run, growth): the
evaluator reads nothing else."""
from __future__ import annotations

import signal

import numpy as np

from .. import progress
from ..adjoints import Evaluation, get_gradient
from ..health import GrowthLog
from ..interrupts import OutOfTime, check
from ..state import SimulationError
from .deadline import now
from .goal import GoalReached, verdict
from .kept import Standing
from .result import history_record


class RouteMerit:
    """What a single-shooting search evaluates: ``problem``'s objective and its gradient by
    the ``gradient`` route (a name or route, :attr:`route`).

    An evaluation keeps the run the route simulated, so judging the goal (``goal``, default
    ``problem``: the true targets where ``problem``'s keyframes aim elsewhere) costs no
    simulation.  A merit of other variables (multiple shooting's
    :class:`~.shooting.merit.ShootingMerit`) gives the same methods.
    """

    def __init__(self, problem, gradient, goal=None):
        self.problem, self.route = problem, get_gradient(gradient)
        self.goal = goal or problem

    def __call__(self, u):
        """The route's :class:`~casadi_keyframe.adjoints.Evaluation` at ``u``."""
        return self.route.evaluate(self.problem, u)

    def describe(self, u, f, found):
        """What an iteration's record says of an evaluated point: ``(controls, objective,
        keyframe error, extra record keys)``, of the goal's true targets (a point judged
        without a gradient: its state terms' part computed on its run)."""
        control = self.goal.control_cost(u)[0]
        if found is not None and found.gradient is None:
            state = self.goal.state_cost(self.run(u, found), gradient=False)[0]
            return u, state + control, state, {}
        if self.goal is not self.problem:
            f = self.goal.state_cost(self.run(u, found), gradient=False)[0] + control
        return u, f, f - control, {}

    def meets(self, goal, found) -> bool:
        """Whether the evaluated point meets ``goal`` (judged on the run it kept)."""
        traj = None if found is None else found.trajectory
        return traj is not None and verdict(goal, traj).met

    def may_meet(self, goal, found) -> bool:
        """Whether the point may meet ``goal`` (the merit's cheap test before its run)."""
        return True

    def run(self, u, found):
        """The controls' own run at ``u``: kept by its evaluation, or simulated now."""
        kept = None if found is None else found.trajectory
        return self.problem.simulate(u, records=False) if kept is None else kept


class Evaluator:
    """Memoised objective and gradient that tracks the best point and failed simulations.

    Search methods ask for f and its gradient at the same point in separate calls (IPOPT)
    or together (L-BFGS-B): the last point's pair is kept, so each point is simulated once.
    It evaluates ``merit`` (default: ``problem``'s objective by the ``gradient`` route,
    :class:`RouteMerit`); a point a search needs no gradient at is judged by its value and
    run alone (:meth:`judge`, ranked with the others by :meth:`offer`).  ``stage`` is the
    stage it serves; ``export`` maps its controls to the final problem's grid for the
    checkpoint (a :class:`~casadi_keyframe.saved.Checkpoint` or None; ``final``: its points
    are the final problem's, comparable with any other there).  The best point is ranked by
    its :class:`~.kept.Standing`: the goal (:mod:`.goal`, the terms and limits of ``goal``,
    default ``problem``) first, then the merit; each iteration's record describes the
    ``report``: the ``"best"`` point so far or the ``"last"`` evaluated; with
    ``failed_best`` a failed evaluation stands as the best while there is no other.  With
    ``stop="goal"`` each iteration raises :class:`~.goal.GoalReached` once the best point
    meets the goal.  ``ranks="effort"`` ranks the points that meet the goal by their control
    cost instead of the merit (a method that lowers the effort under the goal).
    """

    def __init__(self, problem, gradient, checkpoint, *, stage: int = 0, export=None,
                 goal=None, stop: str = "method", merit=None, report: str = "best",
                 failed_best: bool = True, final: bool = True, ranks: str = "objective"):
        self.problem, self.final = problem, final
        if ranks not in ("objective", "effort"):
            raise ValueError(f"Evaluator ranks must be 'objective' or 'effort', got {ranks!r}")
        self.ranks = ranks
        self.merit = RouteMerit(problem, gradient, goal) if merit is None else merit
        self.gradient = self.merit.route
        self.checkpoint, self.stage = checkpoint, stage
        self.export = export or (lambda u: u)
        self.goal, self.stop = goal or problem, stop
        if report not in ("last", "best"):
            raise ValueError(f"Evaluator report must be 'last' or 'best', got {report!r}")
        self.report, self.failed_best = report, failed_best
        self.nfev = 0
        self.judged = 0  # evaluations without a gradient (judge)
        self.failures = 0
        self.last_failure = ""
        self.last_error = None
        self.seconds = 0.0
        self.interrupted = None
        self.timed_out = False  # an evaluation was cut by the time limit (OutOfTime)
        self.start = None  # (objective, keyframe error) at the starting controls
        self.health = GrowthLog()  # each gradient's backward growth (health.GradientError too)
        self.reset()

    def reset(self) -> None:
        """Forget the best point and the last one (a new merit: multiple shooting's round,
        whose multipliers moved)."""
        self.last_u = self.last = self.last_info = None
        self.best_u, self.best_f, self.best_g = None, np.inf, None
        self.best_info = self.best_traj = self._judged = None
        self.best_met = False

    @property
    def njev(self) -> int:
        """Gradients computed: the evaluations that did not fail and asked for one."""
        return self.nfev - self.failures - self.judged

    def counts(self) -> dict:
        """Its evaluations, gradients, seconds and failed simulations, as a
        :class:`~.result.Stage` names them."""
        return {"nfev": self.nfev, "njev": self.njev, "evaluation_seconds": self.seconds,
                "failed_simulations": self.failures}

    def __call__(self, u):
        u = np.array(u, dtype=float).ravel()
        if (self.last_u is not None and self.last[1] is not None
                and np.array_equal(u, self.last_u)):
            return self.last
        t = now()
        try:
            check()  # a signal caught by interrupts.catching stops the search here
            info = self.merit(u)
            f, g = info.value, info.gradient
            self.health.seen(info.growth)
        except SimulationError as err:  # health.GradientError too: a refused gradient
            # a finite value well above the best lets L-BFGS-B backtrack (with inf it gives
            # up: measured, one iteration and "RELATIVE REDUCTION OF F"); IPOPT rejects it too
            self.health.failed(err)
            self.last_error = err
            self.failures += 1
            self.last_failure = str(err)
            best = self.best_f if np.isfinite(self.best_f) else 0.0
            f, g, info = best + 10.0 * (abs(best) + 1.0), np.zeros_like(u), None
        except KeyboardInterrupt as err:  # IPOPT would swallow it: remember, then re-raise
            self.interrupted = getattr(err, "signum", signal.SIGINT)
            raise
        except OutOfTime:  # the evaluation was cut short: it never happened
            self.timed_out = True
            raise
        self.seconds += now() - t
        self.nfev += 1
        self.last_u, self.last, self.last_info = u, (f, g), info
        self._rank(u, f, g, info)
        return f, g

    def _rank(self, u, f, g, info) -> None:
        """Make the point ``u`` the best if its standing beats the best's."""
        met = info is not None and self.merit.meets(self.goal, info)
        if self._standing(u, met, f).beats(self._best_standing()) and (
                info is not None or self.failed_best):
            self.best_u, self.best_f, self.best_g, self.best_info = u, f, g, info
            self.best_traj, self.best_met = None, met

    def _standing(self, u, met: bool, f) -> Standing:
        """A point's :class:`~.kept.Standing` (its control cost too where it meets the goal
        and the evaluator ranks by effort)."""
        effort = (self.goal.control_cost(u)[0] if met and self.ranks == "effort" else None)
        return Standing(met, f, effort)

    def _best_standing(self) -> Standing:
        if self.best_u is None:
            return Standing(False, np.inf)
        return self._standing(self.best_u, self.best_met, self.best_f)

    def judge(self, u, *, records: bool = False) -> Evaluation | None:
        """The problem's objective and run at the controls ``u`` without a gradient (an
        :class:`~casadi_keyframe.adjoints.Evaluation` whose gradient is None; ``records``:
        the run keeps its records, for products made on it), or None where its simulation
        fails; counted as an evaluation (its failure too), timed, a pending signal raised
        first.  It becomes the last point, not the best: :meth:`offer` ranks it."""
        u = np.array(u, dtype=float).ravel()
        t = now()
        found = None
        try:
            check()
            run = self.problem.simulate(u, records=records)
            value = self.problem.state_cost(run, gradient=False)[0]
            found = Evaluation(value + self.problem.control_cost(u)[0], None, run)
        except SimulationError as err:
            self.failures += 1
            self.last_failure = str(err)
        except KeyboardInterrupt as err:
            self.interrupted = getattr(err, "signum", signal.SIGINT)
            raise
        except OutOfTime:
            self.timed_out = True
            raise
        finally:
            self.seconds += now() - t
        self.nfev += 1
        self.judged += found is not None
        self.last_u, self.last_info = u, found
        self.last = (np.nan if found is None else found.value, None)
        return found

    def offer(self, u, *, records: bool = False) -> Evaluation | None:
        """:meth:`judge` the controls ``u`` and rank them with every point evaluated (the
        best point, its objective and run kept, no gradient asked for): a search that needs
        none where it steps (the transcription) offers its iterates here."""
        found = self.judge(u, records=records)
        if found is not None:
            self._rank(self.last_u, found.value, None, found)
        return found

    def take(self, x) -> bool:
        """Make ``x`` the best point (evaluated now if it is not the last), where the merit
        alone does not rank points (IPOPT's iterates on a constrained form); the failed
        simulation's step back stays measured from the lowest value.  False if it fails."""
        self(x)
        if self.last_info is None:
            return False
        self.best_u, self.best_info = np.array(x, dtype=float).ravel(), self.last_info
        self.best_traj = None
        return True

    def best_trajectory(self):
        """The run of the best point's controls (kept, or simulated now without records)."""
        if self.best_traj is None:
            self.best_traj = self.merit.run(self.best_u, self.best_info)
        return self.best_traj

    def verdict(self):
        """The goal's :class:`~.goal.Verdict` at the best point."""
        return verdict(self.goal, self.best_trajectory())

    def check_goal(self, iteration: int) -> None:
        """With ``stop="goal"``: raise :class:`~.goal.GoalReached` if the best point meets
        the goal (judged once per best point)."""
        if self.stop != "goal" or self.best_u is None or self._judged is self.best_u:
            return
        self._judged = self.best_u
        if not self.merit.may_meet(self.goal, self.best_info):
            return
        found = self.verdict()
        if found.checked and found.met:
            raise GoalReached(found, iteration)

    def best_objective(self) -> float:
        """The best point's objective on the goal's true targets (the merit's value where
        they are its own)."""
        return float(self._described("best")[1]) if self.best_u is not None else np.inf

    def keep(self, nit: int = 0) -> None:
        """Offer the best point to the checkpoint (on the final grid, with its objective on
        the goal's true targets, whether it meets the goal, the iterations so far), which
        keeps it only if it is better than what it holds."""
        if self.checkpoint is None or self.best_u is None:
            return
        u, fun = self._described("best")[:2]
        standing = self._standing(u, bool(self.best_met), float(fun))
        self.checkpoint.write(self.export(u), standing,
                              final=self.final, nit=nit, stage=self.stage,
                              stage_dt=float(self.problem.dt))

    def _described(self, which: str):
        if which == "best":
            return self.merit.describe(self.best_u, self.best_f, self.best_info)
        return self.merit.describe(self.last_u, self.last[0], self.last_info)

    def record(self, history, clock, **extra):
        """Append one iteration (at the :attr:`report` point) to ``history``, ``extra`` its
        optional keys, its time read from ``clock`` (the call's :class:`~.deadline.Deadline`);
        the checkpoint gets the best controls on the final grid (``u``), their objective at
        this stage's time step (``fun``), the iterations so far (``nit``), the ``stage`` and
        its ``stage_dt``; the stage's progress counts it."""
        u, objective, keyframe, more = self._described(self.report)
        growth = {} if self.health.last is None else {"gradient_growth": self.health.last}
        history.append(history_record(
            self.problem, u, objective=objective, keyframe_error=keyframe,
            iteration=len(history) + 1, stage=self.stage,
            seconds=clock.elapsed(), nfev=self.nfev, **growth, **extra, **more))
        self.keep(nit=len(history))
        check()
        progress.advance(facts=f"objective {objective:.4g}")
        self.check_goal(len(history))


class MetricView:
    """The evaluator as the optimizer sees it in a smooth metric: a function of z with
    ``u = S z`` (:mod:`.metrics`), its gradient ``S^T g = S g``; ``best_u`` is the z of the
    best controls.  The evaluator itself keeps working in u (history, checkpoint, best)."""

    def __init__(self, ev, metric):
        self.ev, self.metric = ev, metric

    def __call__(self, z):
        f, g = self.ev(self.metric.smooth(z))
        return f, self.metric.smooth(g)

    def offer(self, z, *, records: bool = False):
        """The evaluator's :meth:`~Evaluator.offer` at ``u = S z``."""
        return self.ev.offer(self.metric.smooth(z), records=records)

    @property
    def best_u(self):
        return self.metric.unsmooth(self.ev.best_u)

    @property
    def interrupted(self):
        return self.ev.interrupted

    @property
    def timed_out(self):
        return self.ev.timed_out
