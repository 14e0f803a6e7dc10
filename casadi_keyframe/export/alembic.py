"""Alembic through Blender (``casadi-keyframe export RESULT --format abc``): no maintained
Alembic writer is on PyPI, but Blender writes Alembic, so the cloth goes to Blender as its
rest OBJ and PC2 cache (:mod:`.pc2`, played by a Mesh Cache modifier at ``1 / dt`` frames
per second) and Blender exports ``NAME.abc``, one sample per frame from frame 0.

Blender is found as the ``bpy`` module of this Python (``pip install bpy``, Python 3.11),
else as ``$CASADI_KEYFRAME_BLENDER`` (a ``blender`` binary, or a Python that has ``bpy``),
else as ``blender`` on the PATH.  It runs in a subprocess: Blender's module takes over the
process it is imported into.  A flock has no Alembic export: its USD PointInstancer is what
DCCs read.
"""
from __future__ import annotations

import importlib.util
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

from ..saved import atomic_path
from .pc2 import write_cache

SCRIPT = Path(__file__).with_name("blender_alembic_script.py")
HOW = ("Alembic export needs Blender: pip install bpy (Python 3.11) in this environment, or "
       "install Blender so that 'blender' is on the PATH (Debian: apt-get install blender) or "
       "set CASADI_KEYFRAME_BLENDER to it")


class BlenderError(RuntimeError):
    """Blender ran but did not write the file (the message has its last lines)."""


def find_blender() -> list[str]:
    """The command that runs a Blender script headless (the script's arguments follow
    ``--``), or an ImportError that names the ways to get one."""
    if importlib.util.find_spec("bpy") is not None:
        return [sys.executable, str(SCRIPT)]
    given = os.environ.get("CASADI_KEYFRAME_BLENDER")
    binary = given or shutil.which("blender")
    if binary is None or (given and shutil.which(given) is None):
        raise ImportError(HOW + (f" ({given} was not found)" if given else ""))
    if Path(binary).name.startswith("python"):
        return [binary, str(SCRIPT)]
    return [binary, "-b", "--factory-startup", "--python", str(SCRIPT)]


def write_alembic(scene, path, *, timeout: float = 600.0) -> Path:
    """Write the cloth ``scene`` as an Alembic file at ``path`` through Blender, whole or not
    at all; an ImportError when Blender has no Alembic, a :class:`BlenderError` with
    Blender's last words if it fails otherwise."""
    if scene.faces is None:
        raise ValueError(f"{scene.name}: Alembic export is for cloth; a flock's USD export is "
                         f"a PointInstancer (--format usd)")
    command = find_blender()
    rate = 1.0 / scene.dt
    with tempfile.TemporaryDirectory(prefix="casadi_keyframe_abc_") as tmp:
        pc2, rest = write_cache(scene, tmp)
        with atomic_path(path) as target:
            out = Path(tmp) / "out.abc"
            run = subprocess.run([*command, "--", str(rest), str(pc2), str(out),
                                  str(scene.frames), repr(rate)],
                                 capture_output=True, text=True, timeout=timeout)
            said = run.stdout + run.stderr
            if "NO-ALEMBIC:" in said:
                version = said.split("NO-ALEMBIC: ")[1].splitlines()[0]
                raise ImportError(f"{command[0]}: {version} (Debian's is); Alembic export "
                                  f"needs a Blender with Alembic: pip install bpy (Python "
                                  f"3.11) in this environment, or set CASADI_KEYFRAME_BLENDER "
                                  f"to an official Blender build")
            if run.returncode != 0 or not out.is_file():
                tail = said.strip().splitlines()[-5:]
                raise BlenderError(f"Blender ({command[0]}) did not write the Alembic file "
                                   f"(exit code {run.returncode}): " + " | ".join(tail))
            shutil.move(str(out), str(target))
    return Path(path)


def write_file(scene, folder) -> list[Path]:
    """``NAME.abc`` in ``folder`` (the :data:`~casadi_keyframe.export.FORMATS` writer)."""
    return [write_alembic(scene, Path(folder) / f"{scene.name}.abc")]
