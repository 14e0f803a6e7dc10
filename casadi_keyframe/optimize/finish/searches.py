"""Keyframes held as a constraint while the controls of the last steps before them change:
:func:`land` puts missed keyframes within their tolerances with the least change of the
controls, :func:`lower_effort` lowers the control cost of controls that land and keeps them
landed.

A start that lands (a tracking guess, an earlier solve) sits where the keyframe penalty
curves so sharply, and the cloth's linearized steps switch so often (a spring crossing its
rest length, a contact held or let go), that gradient methods on the penalty objective make
no progress there; a search that stops a little off its keyframes stalls at the same kinks.
Both functions work on the controls of the last ``window`` steps before the last keyframe,
whose effect on the keyframes is short and nearly linear (:class:`~.window.WindowSearch`),
with the residual family's descents on the held keyframes' linearization
(:mod:`.constraint`).  A landing step (:class:`~..residual.descents.Landing`) is halved
(:class:`~..residual.steps.Halving`) until the largest miss (over its tolerance) falls.  An
effort step (:class:`~..residual.descents.Projected`: the control cost's Newton step that
leaves the linearized misses as they are) is damped (:class:`~..residual.steps.Damping`)
until its trial, after at most ``restore`` landing steps from it, is within the tolerances
at a lower control cost: a step that leaves the keyframes by a jump of the piecewise smooth
dynamics is put back, not thrown away.
"""
from __future__ import annotations

import numpy as np

from ...adjoints import get_gradient
from ...controls import StepForces
from ..deadline import Deadline
from ..outcome import CONVERGED, FAILED, LIMIT
from ..residual.steps import Damping, Halving
from ..result import Result
from .window import WindowSearch

LANDED = 0.8  # land() goes on until every miss is within this share of its tolerance


def land(problem, *, u0=None, window: int = 12, position_tolerance: float | None = None,
         velocity_tolerance: float | None = None, maxiter: int = 10, tries: int = 4,
         iterations: int = 60, time_limit: float | None = None, on_keep=None,
         deadline: Deadline | None = None, gradient=None) -> Result:
    """Put the StateKeyframes of controls ``u0`` (default: the problem's start) within their
    tolerances (``position_tolerance`` m and ``velocity_tolerance`` m/s where given, else
    each keyframe's own) by landing steps on the controls of the last ``window``
    steps before the last keyframe: each the least squares landing of the linearized
    keyframes with the least change (LSMR, in the metric of the control cost's Hessian's
    diagonal; a miss the window cannot steer is left), tried at most ``tries`` times, halved
    each time,
    until the largest miss over its tolerance falls (a motion within the physical limits
    staying so), until every miss is within :data:`LANDED` of its tolerance (a margin for
    what follows).  ``iterations``: LSMR iterations per step; ``on_keep(u, trajectory)`` is
    called with each kept step (a checkpoint); ``deadline``: a solve's
    :class:`~.deadline.Deadline`, in place of ``time_limit``; ``gradient``: the route (name
    or object, default the registry's) of the result's gradient.

    Returns a :class:`~.result.Result` (method "land"): status 0 if it ends within the
    tolerances, else 2 when no step brings the keyframes closer, 1 at ``maxiter`` or
    ``time_limit`` (s).
    """
    deadline = deadline or Deadline.start(time_limit)
    _check(problem, window=window, maxiter=maxiter, tries=tries, iterations=iterations,
           position_tolerance=position_tolerance, velocity_tolerance=velocity_tolerance)
    held = WindowSearch(problem, window, (position_tolerance, velocity_tolerance), u0,
                        iterations, get_gradient(gradient), on_keep=on_keep)
    rule = Halving(tries)
    status, message = None, ""
    for _ in range(maxiter):
        if held.within(held.traj, LANDED):
            break
        if deadline.passed():
            status, message = LIMIT, f"time limit reached ({deadline.limit:g} s)"
            break
        if not held.land(rule):
            status, message = FAILED, (f"no landing step of {tries} tried brings the keyframes "
                                       "closer")
            break
    if held.within(held.traj):
        status, message = CONVERGED, "every keyframe within its tolerances"
    elif status is None:
        status, message = LIMIT, f"{maxiter} landing steps taken (maxiter), still off"
    message = f"{message}: misses {_said(held.constraint.misses(held.traj))}"
    return held.result("land", status, message)


def lower_effort(problem, *, window: int = 12, position_tolerance: float | None = None,
                 velocity_tolerance: float | None = None, maxiter: int = 10, tries: int = 6,
                 damping: float = 0.0, restore: int = 2, iterations: int = 60, u0=None,
                 time_limit: float | None = None, keep_objective: bool = False,
                 on_keep=None, quiet: bool = True, deadline: Deadline | None = None,
                 gradient=None) -> Result:
    """Lower the control cost of ``u0`` (default: the problem's start) while every
    StateKeyframe stays within its tolerance (as for :func:`land`), by damped steps on the
    controls of the last ``window`` steps before the last keyframe (module docstring):
    ``damping`` is the first trial's (it grows 4x + 1 per rejected trial, at most ``tries``
    per iteration, and shrinks 3x after a kept step); a trial off the keyframes gets up to
    ``restore`` landing steps; ``keep_objective``: a step must not raise the objective
    either (keyframe misses traded for effort only where the objective gains).  Needs
    per-step forces (:class:`~casadi_keyframe.controls.StepForces`), a positive definite
    control Hessian on the window (Smoothness with ``alpha > 0``), goals that are
    StateKeyframes only (a penalty without a tolerance, such as StrainLimit, is not held:
    ``keep_objective`` weighs it), and a start within the tolerances (:func:`land` finds
    one); ``on_keep``, ``deadline`` and ``gradient`` as for :func:`land`.

    Returns a :class:`~.result.Result` (method "lower_effort"): status 0 when no trial
    step lowers the cost within the tolerances (or ``maxiter`` steps were kept), 1 at
    ``time_limit`` (seconds), 2 when the first iteration keeps no step; ``history`` has one
    record per kept step, ``stages`` one stage, ``njev`` counts the sweeps over the window.
    """
    deadline = deadline or Deadline.start(time_limit)
    _check(problem, window=window, maxiter=maxiter, tries=tries, iterations=iterations,
           position_tolerance=position_tolerance, velocity_tolerance=velocity_tolerance,
           damping=damping, restore=restore)
    held = WindowSearch(problem, window, (position_tolerance, velocity_tolerance), u0,
                        iterations, get_gradient(gradient), keep_objective=keep_objective,
                        on_keep=on_keep)
    rule = Damping(damping, tries)
    if not held.within(held.traj):
        raise ValueError(f"{problem.name}: the start misses its keyframes by "
                         f"{held.constraint.misses(held.traj)} (rms m, m/s), beyond the "
                         f"tolerances {held.constraint.tolerances}: lower_effort keeps a "
                         "landing, it does not find one; start from controls that land (a "
                         "guess, a solve's result, land())")
    status, message = CONVERGED, f"{maxiter} steps kept (maxiter)"
    for _ in range(maxiter):
        if deadline.passed():
            status, message = LIMIT, f"time limit reached ({deadline.limit:g} s)"
            break
        if not held.lower(rule, restore):
            status = CONVERGED if held.history else FAILED
            kept = f"{len(held.history)} steps kept, then " if held.history else ""
            message = (f"{kept}no step of {tries} tried lowers the control cost with the "
                       f"keyframes within their tolerances (damping up to {rule.damping:.3g})")
            break
    return held.result("lower_effort", status, message)


def _said(misses) -> str:
    units = {"x": "m", "v": "m/s"}
    return ", ".join(f"{miss:.3g} {units[kind]}" for kind, miss in misses)



def _check(problem, **settings) -> None:
    """Refuse what the held keyframes cannot do or were given wrong, by name."""
    if not isinstance(problem.controls, StepForces):
        raise ValueError(f"{problem.name}: holding keyframes needs per-step forces "
                         f"(StepForces), got {type(problem.controls).__name__}")
    for name in ("window", "maxiter", "tries", "iterations", "restore"):
        value = settings.get(name, 1)
        least = 0 if name == "restore" else 1
        if not (isinstance(value, (int, np.integer)) and value >= least):
            raise ValueError(f"{name} must be a whole number >= {least}, got {value!r}")
    for name in ("position_tolerance", "velocity_tolerance", "damping"):
        value = settings.get(name)
        if value is not None and not (np.isfinite(value) and value >= 0):
            raise ValueError(f"{name} must be a number >= 0, got {value!r}")
