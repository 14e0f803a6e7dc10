"""Re-solving a shot from a frame (``solve --resume RUN --from-frame K``): RUN's motion up to
frame K is kept as it was, and only the frames after K are searched, against the problem as
it is now (its keyframes and colliders may have changed since RUN).

RUN's controls for the steps before K are held; its state at frame K is the start of a
problem of the steps after K (:func:`tail_problem`: the same model, the integrator's step
numbers moved on by K (:class:`~..integrators.shifted.Shifted`), so colliders and moving
pins see the right time, the keyframes after K moved back by K), warm-started from RUN's
controls after K.  What is written is a whole-shot result (:func:`whole_result`): RUN's
frames 0..K bit for bit, then the tail's; the checkpoint holds whole-shot controls too
(:class:`HeldCheckpoint`), so ``--resume`` goes on from it like from any run.

What cannot change between RUN and now (the cloth's particles, dt, the controls' kind and
the particles they push) is refused naming ``--from-frame``; so is a frame beyond RUN's
steps, before the problem's first keyframe (nothing before a first keyframe is worth
keeping: solve the whole shot) or with no keyframe after it.
"""
from __future__ import annotations

import copy
import dataclasses
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .. import progress
from ..controls import StepForces
from ..integrators.shifted import Shifted
from ..objectives import Objective
from ..objectives.terms import StateTerm
from ..optimize.goal import verdict
from ..optimize.kept import Standing
from ..optimize.outcome import CONVERGED, FAILED
from ..problem import ControlProblem
from ..saved import RESULT, Checkpoint, read_run
from ..simulate import simulate
from ..state import SimulationError, Trajectory

OPTION = "--from-frame"
PIN_TOLERANCE = 1e-9  # m: a pin led as now, to round-off


@dataclass
class HeldStart:
    """A shot re-solved from ``frame``: ``problem`` the steps after it, ``whole`` the shot
    as it is now, ``head`` RUN's controls of the steps before ``frame`` (flat), ``x``, ``v``
    RUN's frames 0..``frame``, ``u0`` the tail's warm start, ``record`` where it came from
    (for the summary's ``resumed_from``)."""

    problem: ControlProblem
    whole: ControlProblem
    frame: int
    head: np.ndarray
    x: np.ndarray
    v: np.ndarray
    u0: np.ndarray
    record: dict

    def checkpoint(self, path, **meta) -> "HeldCheckpoint":
        """The search's checkpoint at ``path``: whole-shot controls, ``from_frame`` in its
        metadata."""
        return HeldCheckpoint(path, self.head, **meta, from_frame=self.frame)

    def breakdown(self, u, tail: Trajectory) -> dict:
        """The whole shot's breakdown with the tail's controls ``u`` and its run ``tail``."""
        return self.whole.breakdown(np.concatenate([self.head, u]), self.spliced(tail))

    def spliced(self, tail: Trajectory) -> Trajectory:
        """RUN's frames 0..K, then the frames after K of ``tail`` (a run of the tail)."""
        return Trajectory(np.concatenate([self.x, tail.x[1:]]),
                          np.concatenate([self.v, tail.v[1:]]), self.whole.dt)


def held_start(whole: ControlProblem, source, frame: int) -> HeldStart:
    """RUN (``source``: a results folder, whose ``result.npz`` is read, or a result file)
    kept up to ``frame`` and the problem of what follows (module docstring); a ValueError
    naming ``--from-frame`` for what cannot be re-solved so."""
    run = read_run(Path(source) / RESULT if Path(source).is_dir() else source)
    path, arrays = run["path"], run["arrays"]
    if run["meta"].get("problem") != whole.name:
        raise ValueError(f"--resume {path} holds a run of problem {run['meta'].get('problem')!r}"
                         f", not {whole.name!r}")
    if "x" not in arrays:
        raise ValueError(f"{OPTION}: {path} holds no motion (a checkpoint): give the run's "
                         f"folder or its {RESULT}, whose frames are kept")
    x, v = arrays["x"], arrays["v"]
    steps = x.shape[0] - 1
    _check_same(whole, x, float(arrays["dt"]), run["u"], path)
    _check_frame(whole, frame, steps, path)
    _check_pins(whole, x[:frame + 1], path)
    block = whole.controls.idx.size * whole.model.dim
    head = np.array(run["u"][:frame * block])
    tail = np.zeros((whole.steps - frame) * block)
    kept = run["u"][frame * block:frame * block + tail.size]
    tail[:kept.size] = kept
    carried = _carried(whole, head, tail, x[:frame + 1], path)
    problem = tail_problem(whole, frame, x[frame], v[frame], carried, whole.guess_rule)
    u0, start = better_start(problem, tail)
    record = {"path": str(path), "nit": run["meta"].get("nit"), "fun": run["meta"].get("fun"),
              "from_frame": frame, "start": start}
    return HeldStart(problem, whole, frame, head, x[:frame + 1], v[:frame + 1], u0, record)


def better_start(problem, kept) -> tuple[np.ndarray, str]:
    """``(controls, which)``: RUN's controls after the frame (``kept``) or, when they miss
    the goal and the problem makes its own start (a guess rule: a controller that tracks the
    keyframes as they are now), that one on the frames after K if it stands better (the goal
    met first, then the objective: :class:`~..optimize.kept.Standing`; a start whose
    simulation fails stands last)."""
    ran = _standing(problem, kept)
    if problem.guess_rule is None or (ran is not None and ran.met):
        return kept, "RUN's controls"
    try:
        own = problem.initial_controls()
    except SimulationError:  # the controller's own runs fail: RUN's controls it is
        return kept, "RUN's controls"
    mine = _standing(problem, own)
    if mine is not None and mine.beats(ran):
        return own, "the problem's own start (its guess on the frames after K)"
    return kept, "RUN's controls"


def _standing(problem, u) -> Standing | None:
    """Where the controls ``u`` stand on ``problem`` (None: its simulation fails)."""
    try:
        traj = problem.simulate(u, records=False)
    except SimulationError:
        return None
    return Standing(verdict(problem, traj).met, problem.breakdown(u, traj)["objective"])


def _check_same(whole, x, dt: float, u, path) -> None:
    """Refuse a RUN whose cloth, dt or controls differ from the problem's now."""
    if x.shape[1:] != whole.x0.shape:
        raise ValueError(f"{OPTION}: {path} moves {x.shape[1]} particles, {whole.name} now "
                         f"has {whole.model.n}: the cloth cannot change; solve the whole shot")
    if not np.isclose(dt, whole.dt, rtol=1e-12, atol=0):
        raise ValueError(f"{OPTION}: {path} was solved at dt {dt:.6g} s, {whole.name} now at "
                         f"{whole.dt:.6g} s: dt cannot change; give dt={dt:.6g}")
    block = whole.controls.idx.size * whole.model.dim
    if not isinstance(whole.controls, StepForces) or u.size != (x.shape[0] - 1) * block:
        raise ValueError(f"{OPTION}: keeps per-step forces of the same free particles, and "
                         f"{path}'s {u.size} controls over {x.shape[0] - 1} steps are not "
                         f"{whole.controls.label} on {whole.controls.idx.size} particles: the "
                         "controls' kind and the pins cannot change; solve the whole shot")


def _check_pins(whole, x, path) -> None:
    """Refuse a RUN whose frames ``x`` do not move the problem's prescribed particles (its
    pins, pinned or moving) as the problem does now: the pins changed."""
    model, dt, pins = whole.model, whole.dt, whole.model.prescribed_particles()
    if not pins.size:
        return
    gaps = [np.abs(x[0, pins] - whole.x0[pins]).max()]
    for n in range(len(x) - 1):
        led = x[n] + dt * model.prescribed_velocity(x[n], n * dt, dt)
        gaps.append(np.abs(x[n + 1, pins] - led[pins]).max())
    if max(gaps) > PIN_TOLERANCE:
        raise ValueError(f"{OPTION}: {path} does not move the pinned vertices as {whole.name} "
                         f"does now (up to {max(gaps):.3g} m off, first at frame "
                         f"{int(np.argmax(np.array(gaps) > PIN_TOLERANCE))}): the pins cannot "
                         "change (pins, pin_group, pin_box, pin_motion, pin_body); solve the "
                         "whole shot")


def _check_frame(whole, frame: int, steps: int, path) -> None:
    """Refuse a frame beyond RUN, before the first keyframe, or with no keyframe after it."""
    keys = sorted(t.frame for t in whole.objective_terms.state_terms)
    if not 0 <= frame <= steps:
        raise ValueError(f"{OPTION} {frame} is beyond {path}'s {steps} steps: give a frame in "
                         f"{keys[0]}..{min(steps, whole.steps) - 1}")
    if frame < keys[0]:
        raise ValueError(f"{OPTION} {frame} is before the first keyframe (frame {keys[0]}): "
                         "nothing before a first keyframe is worth keeping; solve the whole "
                         f"shot instead, without {OPTION}")
    if frame >= min(keys[-1], whole.steps):
        raise ValueError(f"{OPTION} {frame} leaves no keyframe after it (the last is at frame "
                         f"{keys[-1]}): nothing to solve; give a frame before {keys[-1]}")


def _carried(whole, head, tail, kept, path):
    """What RUN's step before the frame left to the next (:meth:`carry`), from the problem
    as it is now stepped under RUN's held controls; a note if it moves those frames other
    than RUN did (something before the frame changed: RUN's frames are kept all the same)."""
    frame = kept.shape[0] - 1
    forces = whole.external + whole.controls.external(np.concatenate([head, tail]))
    run = simulate(whole.integrator, whole.model, whole.x0, whole.v0, forces[:frame], whole.dt)
    carried = whole.integrator.carry(whole.model, run.records[-1]) if run.records else None
    whole.integrator.release(run)
    gap = float(np.abs(run.x - kept).max())
    if gap > 0:
        progress.note(f"{OPTION}: the problem as it is now moves frames 0..{frame} up to "
                      f"{gap:.3g} m from {path}'s (the start, the pins or a collider changed "
                      f"before frame {frame}); {path}'s frames are kept")
    return carried


def tail_problem(whole: ControlProblem, frame: int, x, v, carried, guess=None) -> ControlProblem:
    """``whole``'s steps after ``frame``, from the state ``(x, v)``: step n is the whole's
    step ``frame + n`` (after one that left ``carried``), each keyframe after ``frame``
    ``frame`` frames earlier, those up to it dropped, a trajectory term's ``until`` (s)
    moved back as far; ``guess``: its start (flat controls or a guess rule)."""
    terms = []
    for term in whole.objective_terms.terms:
        if isinstance(term, StateTerm):
            if term.frame > frame:
                terms.append(term.at_frame(term.frame - frame))
        elif getattr(term, "until", None) is not None:
            moved = copy.copy(term)
            moved.until = term.until - frame * whole.dt
            terms += [moved] if moved.until > 0 else []
        else:
            terms.append(term)
    steps = whole.steps - frame
    return ControlProblem(model=whole.model, integrator=Shifted(whole.integrator, frame, carried),
                          x0=x, v0=v, steps=steps, dt=whole.dt,
                          controls=whole.controls.for_steps(steps), objective=Objective(terms),
                          external=whole.external[frame:], name=whole.name, view=whole.view,
                          guess=guess, inputs=whole.inputs, limits=whole.limits)


def whole_result(held: HeldStart, result):
    """The tail's ``result`` as a result of the whole shot: RUN's held controls and frames
    0..K before the tail's, the whole problem's breakdown and objective there; the gradient
    of the held controls is not computed (NaN).  The tail's goal met, the whole shot's is
    judged too: a keyframe or a limit RUN's kept frames miss makes it a failed search that
    says so."""
    u = np.concatenate([held.head, result.x])
    traj = held.spliced(result.trajectory)
    breakdown = held.breakdown(result.x, result.trajectory)
    jac = np.concatenate([np.full(held.head.size, np.nan), result.jac])
    status, message = result.status, result.message
    judged = verdict(held.whole, traj)
    if status == CONVERGED and judged.checked and not judged.met:
        status = FAILED
        message = (f"frames {held.frame + 1}.. meet their goal, the whole shot does not "
                   f"({judged.describe()}): frames 0..{held.frame} are "
                   f"{held.record['path']}'s; solve from an earlier frame, or the whole shot")
    return dataclasses.replace(result, x=u, fun=breakdown["objective"], jac=jac,
                               trajectory=traj, breakdown=breakdown, status=status,
                               success=status == CONVERGED, message=message)


class HeldCheckpoint(Checkpoint):
    """A :class:`~..saved.Checkpoint` of a tail's search that writes whole-shot controls:
    the held ``head`` before each point searched."""

    def __init__(self, path, head, **meta):
        super().__init__(path, **meta)
        self.head = np.asarray(head, dtype=float)

    def with_meta(self, generation: int | None = None, **more) -> "HeldCheckpoint":
        base = super().with_meta(generation, **more)
        out = HeldCheckpoint(self.path, self.head, **base.meta)
        out._held, out.generation = base._held, base.generation
        return out

    def write(self, u, standing, **fields) -> bool:
        return super().write(np.concatenate([self.head, np.asarray(u, float)]), standing,
                             **fields)
