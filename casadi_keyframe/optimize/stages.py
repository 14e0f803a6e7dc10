"""The problems one :func:`~.optimize.solve` goes through, coarse to fine, on three axes:
coarser meshes of a cloth (space), a homotopy of the model (e.g. contact made soft and thick
first, then the model's own) and the time steps of a continuation (time); and how controls
pass from one to the next."""
from __future__ import annotations

from .transfer import carry_to_mesh


def stage_problems(problem, continuation, resolutions=None, homotopy=None,
                   coarser_only: bool = False) -> list:
    """The problems a continuation solves in turn, coarse to fine; the last is ``problem``.

    For every mesh of ``resolutions`` (see :func:`coarser_meshes`; with ``coarser_only``
    those coarser than ``problem`` only, the others left out) and then ``problem``: the
    mesh at each level of ``homotopy`` (see :func:`homotopy_levels`) and then as it is, each
    at the time stages of ``continuation``.  ``continuation`` None means one time stage.
    Otherwise its time steps must decrease strictly and end at ``problem.dt`` (appended if
    missing), each dividing the horizon into whole steps with every keyframe on its grid
    (else ValueError, from ``resampled``).
    """
    meshes = coarser_meshes(problem, resolutions, coarser_only) + [problem]
    return [stage for mesh in meshes for level in homotopy_levels(mesh, homotopy)
            for stage in _time_stages(level, continuation)]


def homotopy_levels(problem, homotopy) -> list:
    """``problem`` at each level of ``homotopy`` and then itself: a level is a problem or a
    dict of build overrides (:meth:`~.problem.ControlProblem.at_resolution`, e.g. a cape's
    ``{"contact": 3}``, its contact three times softer and thicker), checked to be the same
    problem on the same particles, steps and controls."""
    if homotopy is None:
        return [problem]
    if isinstance(homotopy, (dict, str)) or not hasattr(homotopy, "__iter__"):
        raise ValueError(f"homotopy must be a list of problems or of build overrides such as "
                         f"{{'contact': 3}}, first to last, got {homotopy!r}")
    levels = [problem.at_resolution(**h) if isinstance(h, dict) else h for h in homotopy]
    for h, level in zip(homotopy, levels):
        if not (isinstance(level, type(problem)) and level.model.n == problem.model.n
                and level.steps == problem.steps and level.size == problem.size):
            raise ValueError(f"homotopy: {h!r} is not {problem.name} on its {problem.model.n} "
                             f"particles, {problem.steps} steps and {problem.size} controls "
                             "with another model: a level changes the model, not the problem")
    return levels + [problem]


def coarser_meshes(problem, resolutions, coarser_only: bool = False) -> list:
    """The problems of ``resolutions`` (None or a list of problems or build-override dicts),
    checked to be the same kind of problem on ever finer meshes, all coarser than
    ``problem`` (with ``coarser_only``: those that are not are left out, as a problem file's
    default meshes are for a problem built that coarse itself)."""
    if resolutions is None:
        return []
    if isinstance(resolutions, (dict, str)) or not hasattr(resolutions, "__iter__"):
        raise ValueError(f"resolutions must be a list of coarser problems or of build "
                         f"overrides such as {{'rows': 12, 'cols': 12}}, got {resolutions!r}")
    meshes = [problem.at_resolution(**r) if isinstance(r, dict) else r for r in resolutions]
    if coarser_only:
        kept = [(r, m) for r, m in zip(resolutions, meshes) if m.model.n < problem.model.n]
        resolutions, meshes = [r for r, _ in kept], [m for _, m in kept]
    sizes = []
    for r, mesh in zip(resolutions, meshes):
        if not isinstance(mesh, type(problem)):
            raise ValueError(f"resolutions: {r!r} is neither a problem nor a dict of build "
                             "overrides")
        if mesh.horizon != problem.horizon or type(mesh.controls) is not type(problem.controls):
            raise ValueError(f"resolutions: {mesh.name} on {mesh.model.n} particles is not the "
                             f"same problem as {problem.name} ({mesh.steps} steps of "
                             f"{mesh.dt:.6g} s, {mesh.controls.label}; the problem: "
                             f"{problem.steps} of {problem.dt:.6g} s, {problem.controls.label})")
        sizes.append(mesh.model.n)
    if any(b <= a for a, b in zip(sizes, sizes[1:] + [problem.model.n])):
        raise ValueError(f"resolutions must go coarse to fine, each mesh with fewer particles "
                         f"than the next and than the problem's {problem.model.n}; got "
                         f"{sizes} particles")
    return meshes


def _time_stages(problem, continuation) -> list:
    """``problem`` at each time step of ``continuation`` (see :func:`stage_problems`)."""
    if continuation is None:
        return [problem]
    try:
        dts = [float(dt) for dt in continuation]
    except (TypeError, ValueError):
        raise ValueError(f"continuation must be a list of time steps in seconds, coarse to "
                         f"fine, got {continuation!r}") from None
    if not dts:
        raise ValueError("continuation is empty: give time steps coarse to fine, e.g. "
                         f"[{4 * problem.dt:.6g}, {2 * problem.dt:.6g}], or leave it out")
    if abs(dts[-1] - problem.dt) <= 1e-9 * problem.dt:
        dts[-1] = problem.dt
    else:
        dts.append(problem.dt)
    if any(fine >= coarse for coarse, fine in zip(dts, dts[1:])):
        raise ValueError(
            f"{problem.name}: continuation time steps must decrease strictly, coarse to fine, "
            f"and end at the problem's dt = {problem.dt:.6g} s (appended if missing); got "
            f"{[float(f'{d:.6g}') for d in continuation]}.  To solve at a finer step, build the "
            "problem with that dt")
    return [problem.resampled(dt) for dt in dts[:-1]] + [problem]


def stage_name(problem) -> str:
    """``"144 particles, dt = 0.0166667 s"``: which stage a message speaks of."""
    return f"{problem.model.n} particles, dt = {problem.dt:.6g} s"


def carry(source, u, target):
    """Controls ``u`` of problem ``source`` on the grid (and mesh) of problem ``target``."""
    if source is target:
        return u
    if source.model is target.model or (source.model.n == target.model.n
                                        and source.steps == target.steps
                                        and source.size == target.size):
        return source.controls.resample(u, target.steps)  # same particles: the same forces
    return carry_to_mesh(source, u, target)
