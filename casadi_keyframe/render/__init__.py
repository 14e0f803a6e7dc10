"""Pictures of a problem's trajectory and of an optimizer's history, drawn with matplotlib.

``animate`` writes a GIF and ``snapshot`` a PNG of small multiples at the keyframes, each
handing over by problem kind: a blend between source clips to :mod:`.blend` (the clips and
the blend side by side), a cloth (a model with a surface) to :mod:`.cloth` (3-D), a flock to
:mod:`.flock` (seen from above).  ``convergence`` writes a PNG of the optimizer's history.
All draw with the Agg backend, close their figures and write each file whole or not at all
(:mod:`.frames`).
"""
import matplotlib

matplotlib.use("Agg")  # before any submodule imports pyplot
from ..models.base import Surface  # noqa: E402
from ..views import BlendView  # noqa: E402
from . import blend, cloth, flock  # noqa: E402
from .convergence import convergence  # noqa: E402
from .frames import keyframes, select_frames, write_gif  # noqa: E402

__all__ = ["animate", "blend", "cloth", "convergence", "flock", "keyframes", "select_frames",
           "snapshot", "write_gif"]


def renderer(problem):
    """The module that draws ``problem``: blend, cloth or flock."""
    if isinstance(problem.view, BlendView):
        return blend
    if isinstance(problem.model, Surface):
        return cloth
    return flock


def animate(problem, trajectory, path, *, fps: int | None = None,
            max_frames: int | None = None, title=None, limit: float | None = None):
    """Write an animated GIF of ``trajectory``; returns the path.

    About ``max_frames + 1`` frames, always with every keyframe and the last frame; ``fps``
    and ``max_frames`` default to the renderer's own (flock 20 and 150, cloth and blend 15
    and 80); ``title`` overrides the problem name in the title; ``limit``: the seconds its
    drawing may take, past which the frames left are thinned (:func:`.frames.write_gif`).
    """
    given = {k: v for k, v in (("fps", fps), ("max_frames", max_frames)) if v is not None}
    return renderer(problem).animate(problem, trajectory, path, title=title, limit=limit,
                                     **given)


def snapshot(problem, trajectory, path, frames=None, title=None):
    """Write a PNG of small multiples, by default at the first frame, each keyframe and the
    last (a blend: the start, two between and the end of the blend); ``title`` in place of
    the problem's name; returns the path."""
    return renderer(problem).snapshot(problem, trajectory, path, frames, title=title)
