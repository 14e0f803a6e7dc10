"""Results where animators and researchers work: USD, PC2 point caches, OBJ sequences and a
self-contained HTML viewer (``casadi-keyframe export RESULT_DIR --format ...``).

:func:`export` reads a results folder once (:mod:`..saved`), turns it into plain arrays
(:mod:`.scene`) and hands them to one writer per format:

========  =================================================  ===========================
format    files (in the results folder, or ``out``)           needs
========  =================================================  ===========================
``usd``   ``NAME.usd``: one stage, see :mod:`.usd`             ``casadi_keyframe[usd]``
``pc2``   ``NAME.pc2`` + ``NAME_rest.obj`` (:mod:`.pc2`)       nothing
``obj``   ``obj/NAME_0000.obj`` ... one per frame (:mod:`.obj`) nothing
``html``  ``viewer.html``: the interactive viewer (:mod:`.viewer`)  ``casadi_keyframe[viewer]``
========  =================================================  ===========================
"""
from __future__ import annotations

from pathlib import Path

from .scene import Scene, scene_of

FORMATS = ("usd", "pc2", "obj", "html")
VIEWER = "viewer.html"

__all__ = ["FORMATS", "Scene", "export", "export_scene", "scene_of"]


def check_format(fmt: str) -> str:
    """``fmt`` if it is one of :data:`FORMATS`, else a ValueError listing them."""
    if fmt not in FORMATS:
        raise ValueError(f"unknown export format {fmt!r}: choose one of {', '.join(FORMATS)}")
    return fmt


def export_scene(scene: Scene, fmt: str, out) -> list[Path]:
    """Write ``scene`` in format ``fmt`` into the folder ``out``; the files written."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    if check_format(fmt) == "usd":
        from .usd import write_usd
        return [write_usd(scene, out / f"{scene.name}.usd")]
    if fmt == "pc2":
        from .pc2 import write_cache
        return write_cache(scene, out)
    if fmt == "obj":
        from .obj import write_sequence
        return write_sequence(scene, out / "obj")
    from .viewer import write_viewer
    return [write_viewer(scene, out / VIEWER)]


def export(source, fmt: str, *, out=None) -> list[Path]:
    """Export the result in ``source`` (a results folder or its ``result.npz``) as ``fmt``
    (one of :data:`FORMATS`) into ``out`` (default: the result's folder); returns the files
    written.  Refused with a ValueError for an unknown format, a FileNotFoundError for a
    folder with no result, an ImportError naming the extra to install when ``usd`` or
    ``html`` lacks its library."""
    from ..saved import load_saved

    check_format(fmt)
    _check_library(fmt)
    saved = load_saved(source)
    return export_scene(scene_of(saved.problem, saved.trajectory), fmt,
                        saved.path.parent if out is None else out)


def _check_library(fmt: str) -> None:
    """Fail before reading the result if ``fmt`` needs a library that is missing."""
    if fmt == "usd":
        from .usd import pxr_modules
        pxr_modules()
    elif fmt == "html":
        from .viewer import plotly_module
        plotly_module()
