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
``abc``   ``NAME.abc``: Alembic, cloth only (:mod:`.alembic`)  Blender (``bpy`` or a binary)
========  =================================================  ===========================
"""
from __future__ import annotations

from pathlib import Path

from .scene import Scene, scene_of

FORMATS = ("usd", "pc2", "obj", "html", "abc")
VIEWER = "viewer.html"

__all__ = ["FORMATS", "Scene", "check_library", "export", "export_scene", "scene_of",
           "write_outputs"]


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
    if fmt == "abc":
        from .alembic import write_alembic
        return [write_alembic(scene, out / f"{scene.name}.abc")]
    from .viewer import write_viewer
    return [write_viewer(scene, out / VIEWER)]


def export(source, fmt: str, *, out=None) -> list[Path]:
    """Export the result in ``source`` (a results folder or its ``result.npz``) as ``fmt``
    (one of :data:`FORMATS`) into ``out`` (default: the result's folder); returns the files
    written.  Refused before the result is read with a ValueError for an output folder
    that cannot be written or an unknown format, a FileNotFoundError for a
    folder with no result, an ImportError naming the extra to install when ``usd`` or
    ``html`` lacks its library."""
    from ..saved import writable_folder
    from ..saved import load_saved, saved_file

    check_library(fmt)
    path = saved_file(source)
    if out is None:
        out = writable_folder(path.parent, "--out", fix="export writes beside the result "
                              "unless given --out (out= in Python): give a folder you can "
                              "write")
    else:
        out = writable_folder(out, "--out")
    saved = load_saved(path)
    return export_scene(scene_of(saved.problem, saved.trajectory), fmt, out)


def check_library(fmt: str) -> None:
    """A ValueError for an unknown ``fmt``, an ImportError naming the extra to install if
    it needs a library that is missing: checked before a result is read or a solve starts."""
    if check_format(fmt) == "usd":
        from .usd import pxr_modules
        pxr_modules()
    elif fmt == "html":
        from .viewer import plotly_module
        plotly_module()
    elif fmt == "abc":
        from .alembic import find_blender
        find_blender()


def write_outputs(problem, trajectory, out, formats=(), *, viewer: bool = True) -> list[Path]:
    """What ``solve`` writes beside its pictures: the viewer (skipped with a one-line note
    when plotly is missing) and each of ``formats``; returns the files written."""
    scene, written = scene_of(problem, trajectory), []
    if viewer and "html" not in formats:
        try:
            written += export_scene(scene, "html", out)
        except ImportError as err:
            print(f"  viewer skipped: {err}")
    for fmt in formats:
        written += export_scene(scene, fmt, out)
    return written
