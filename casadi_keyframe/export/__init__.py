"""Results where animators and researchers work: USD, PC2 point caches, OBJ sequences, the
self-contained HTML viewer and Alembic (``casadi-keyframe export RESULT_DIR --format ...``).

:func:`export` reads a results folder once (:mod:`..saved`), turns it into plain arrays
(:mod:`.scene`) and hands them to the format's writer in :data:`FORMATS`, the one table of
formats: what each writes, what it needs, its writer and the check of its library.
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from .. import progress
from . import alembic, obj, pc2, usd, viewer
from .scene import Scene, scene_of

@dataclass(frozen=True)
class Format:
    """One export format: ``write(scene, folder) -> [paths]``, ``check()`` (an ImportError
    naming what to install when its library is missing), the ``files`` it writes and what
    it ``needs``."""

    write: Callable
    check: Callable
    files: str
    needs: str = "nothing"


def _nothing() -> None:
    """A format that needs no library."""


FORMATS = {
    "usd": Format(usd.write_stage, usd.pxr_modules, "NAME.usd, one stage",
                  "casadi_keyframe[usd]"),
    "pc2": Format(pc2.write_cache, _nothing, "NAME.pc2 and its rest mesh NAME_rest.obj "
                  "(Blender's Mesh Cache modifier)"),
    "obj": Format(obj.write_frames, _nothing, "obj/NAME_0000.obj ... one per frame"),
    "html": Format(viewer.write_page, viewer.plotly_module, "viewer.html, the interactive "
                   "viewer", "casadi_keyframe[viewer]"),
    "abc": Format(alembic.write_file, alembic.find_blender, "NAME.abc, Alembic of a cloth",
                  "Blender: the bpy module or a blender binary"),
}


def check_format(fmt: str) -> Format:
    """The :data:`FORMATS` entry of ``fmt``, else a ValueError listing them."""
    if fmt not in FORMATS:
        raise ValueError(f"unknown export format {fmt!r}: choose one of {', '.join(FORMATS)}")
    return FORMATS[fmt]


def format_help() -> str:
    """Each format, what it writes and what it needs: the command line's help."""
    return "; ".join(f"{name}: {f.files}" + ("" if f.needs == "nothing" else
                                             f" (needs {f.needs})")
                     for name, f in FORMATS.items())


def export_scene(scene: Scene, fmt: str, out) -> list[Path]:
    """Write ``scene`` in format ``fmt`` into the folder ``out``; the files written (the
    work said as it goes: :mod:`~casadi_keyframe.progress`)."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    with progress.task(f"exporting {fmt} ({scene.frames} frames)"):
        return check_format(fmt).write(scene, out)


def export(source, fmt: str, *, out=None) -> list[Path]:
    """Export the result in ``source`` (a results folder or its ``result.npz``) as ``fmt``
    (one of :data:`FORMATS`) into ``out`` (default: the result's folder); returns the files
    written.  Refused before the result is read with a ValueError for an output folder
    that cannot be written or an unknown format, a FileNotFoundError for a
    folder with no result, an ImportError naming the extra to install when ``usd`` or
    ``html`` lacks its library."""
    from ..saved import load_saved, saved_file, writable_folder

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
    check_format(fmt).check()


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
