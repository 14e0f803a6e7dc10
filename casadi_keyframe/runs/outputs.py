"""What a run leaves beside its result: its pictures, the viewer and the exports, and the
same drawn or written again from a saved run (``casadi-keyframe render`` and ``export``)."""
from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

from .. import progress
from ..interrupts import check
from .exits import guarded, stopped

DRAW_LIMIT = 60.0  # s: the time an animation may take to draw unless --draw-limit says


def draw(problem, trajectory, result, out, *, animation: bool = True, start=None,
         limit: float | None = None, subtitle: str = "") -> None:
    """convergence.png (its start point alone for a search of no iteration), keyframes.png,
    animation.gif (its drawing held to ``limit`` seconds, default :data:`DRAW_LIMIT`: past
    it fewer frames) and, given the ``start`` trajectory of a cloth's search,
    start_and_result.png (the two side by side); each picture's title names the problem
    and ``subtitle`` (the overrides the run used), and each says as it is drawn."""
    from .. import render

    out = Path(out)
    title = f"{problem.name} ({subtitle})" if subtitle else None
    pictures = 2 + (start is not None and render.renderer(problem) is render.cloth) + animation
    with progress.task(f"{problem.name}: drawing the pictures", pictures, "pictures"):
        render.convergence(result, out / "convergence.png")
        progress.advance()
        render.snapshot(problem, trajectory, out / "keyframes.png", title=title)
        progress.advance()
        if start is not None and render.renderer(problem) is render.cloth:
            render.cloth.side_by_side(problem, {"start": start, "result": trajectory},
                                      out / "start_and_result.png", title=title)
            progress.advance()
        if animation:
            render.animate(problem, trajectory, out / "animation.gif", title=title,
                           limit=DRAW_LIMIT if limit is None else limit)
            progress.advance()


def write_outputs(spec, trajectory) -> None:
    """The viewer and the ``--export`` formats, each file named as it is written."""
    from ..export import write_outputs as write_exports

    paths = write_exports(spec.problem, trajectory, spec.out, spec.exports, viewer=spec.viewer)
    if paths:
        shown = [str(p) for p in paths[:3]] + ([f"... {len(paths) - 3} more"] if len(paths) > 3 else [])
        print(f"  exported: {', '.join(shown)}")


def run_export(source, formats, *, out=None) -> int:
    """Export a saved run (``casadi-keyframe export``) in each of ``formats``; exit code 0."""
    from ..export import check_library, export

    for fmt in formats:  # every format's library before any file is written
        check_library(fmt)
    with progress.reporting():
        for fmt in formats:
            paths = export(source, fmt, out=out)
            more = f" ... ({len(paths)} files)" if len(paths) > 2 else ""
            print(f"{fmt}: {', '.join(str(p) for p in paths[:2])}{more}")
    return 0


def run_render(source, *, animation: bool = True, limit: float | None = None) -> int:
    """Draw a saved run's pictures again (``casadi-keyframe render``; the animation within
    ``limit`` seconds, see :func:`draw`); the exit code."""
    def work(caught):
        with progress.reporting():
            code = render_saved(source, animation, limit)
        check()
        return code

    return guarded(work, lambda signum: f"\n{stopped(signum)}: drawing stopped; the "
                                         "pictures drawn so far are whole")


def render_saved(source, animation: bool, limit: float | None = None) -> int:
    from ..saved import load_saved, saved_file, writable_folder

    path = saved_file(source)
    writable_folder(path.parent, "the results folder", fix="render draws beside the run "
                    "file: copy the folder somewhere you can write and render the copy")
    saved = load_saved(path)
    prob, out = saved.problem, saved.path.parent
    draw(prob, saved.trajectory, _history(saved.meta, saved.arrays), out, animation=animation,
         limit=limit)
    print(f"{prob.name}: pictures drawn in {out}/ from {saved.path.name}")
    return 0


def _history(meta, arrays) -> SimpleNamespace:
    """What :func:`render.convergence` reads, from a result.npz's arrays."""
    objective = arrays.get("history_objective", ())
    history = [{"iteration": i + 1, "objective": float(f),
                "keyframe_error": float(arrays["history_keyframe_error"][i]),
                "seconds": float(arrays["history_seconds"][i]),
                **{key: cast(arrays[f"history_{key}"][i])
                   for key, cast in (("stage", int), ("dt", float), ("particles", int),
                                     ("round", int))
                   if f"history_{key}" in arrays},  # older files lack some
                } for i, f in enumerate(objective)]
    for record in history:
        if record.get("round", 0) < 0:  # written as -1: no rounds
            del record["round"]
    start = {k: float(arrays[f"start_{k}"]) if f"start_{k}" in arrays else None
             for k in ("objective", "keyframe_error")}
    return SimpleNamespace(history=history, start=start, method=meta.get("method", "?"),
                           gradient=meta.get("gradient", "?"))
