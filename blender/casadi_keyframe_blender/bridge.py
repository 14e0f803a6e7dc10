"""What the add-on does outside Blender's API, in plain Python (no bpy, no numpy), so it can
be tested without Blender: mesh files written for the solver (the cloth, its targets, the
colliders), the solve's command line, the progress lines it prints, its misses, and point
caches carried into an object's local space.

The add-on never imports casadi_keyframe: it runs the user's ``casadi-keyframe`` command (the
path in the add-on's preferences) in a subprocess and reads the files it leaves.
"""
from __future__ import annotations

import json
import re
import struct
from fractions import Fraction
from pathlib import Path

PROBLEM = "mesh_keyframes"
_PC2 = struct.Struct("<12siiffi")
_TARGET = re.compile(r"^(?P<name>.*?)\s*@\s*(?P<frame>\d+)$")


def obj_text(vertices, polygons, comment: str = "") -> str:
    """OBJ text of ``vertices`` (x, y, z triples, metres) and ``polygons`` (0-based vertex
    index lists, any size): the vertices in the mesh's own order, which the solver keeps."""
    lines = [f"# {comment}"] if comment else []
    lines += [f"v {x!r} {y!r} {z!r}" for x, y, z in vertices]
    lines += ["f " + " ".join(str(i + 1) for i in poly) for poly in polygons]
    return "\n".join(lines) + "\n"


def write_body(folder, name: str, frames, polygons) -> Path:
    """A collider's mesh file for the solver from ``frames`` (per scene frame from the
    start, a list of world (x, y, z)): ``NAME.obj`` if it never moves, else the point cache
    ``NAME.pc2`` (one sample per frame) beside its rest mesh ``NAME_rest.obj``."""
    folder = Path(folder)
    if all(frame == frames[0] for frame in frames[1:]):
        path = folder / f"{name}.obj"
        path.write_text(obj_text(frames[0], polygons, f"collider {name}, world space"))
        return path
    (folder / f"{name}_rest.obj").write_text(
        obj_text(frames[0], polygons, f"collider {name} at the start, world space"))
    return write_pc2(folder / f"{name}.pc2", frames)


def frame_from_name(name: str):
    """The frame a target's name asks for (``"wave@40"`` -> 40), or None."""
    match = _TARGET.match(name.strip())
    return int(match["frame"]) if match else None


def fps_fraction(fps: int, fps_base: float) -> str:
    """A scene's frame time as the solver's ``dt`` (``"1/60"``; ``fps_base`` 1.001 gives
    ``"1001/30000"``), exact so that one result frame is one scene frame."""
    dt = Fraction(fps_base).limit_denominator(100000) / int(fps)
    return f"{dt.numerator}/{dt.denominator}"


def solve_command(executable: str, *, cloth, targets, pins, dt: str, steps: int, out,
                  maxiter: int | None = None, bodies=(), extra=()) -> list[str]:
    """The ``casadi-keyframe solve mesh_keyframes`` command line: ``targets`` is a list of
    ``(frame, file)``, ``bodies`` the colliders' mesh files (:func:`write_body`); the result
    is also exported as a PC2 point cache."""
    keyframes = ",".join(f"{frame}:{path}" for frame, path in sorted(targets))
    args = [str(executable), "solve", PROBLEM, "--set", f"cloth={cloth}", "--set",
            f"keyframes={keyframes}", "--set", f"dt={dt}", "--set", f"steps={int(steps)}"]
    if pins:
        args += ["--set", "pins=" + ",".join(str(int(i)) for i in sorted(pins)) + ","]
    if bodies:
        args += ["--set", "bodies=" + ",".join(str(b) for b in bodies)]
    if maxiter:
        args += ["--maxiter", str(int(maxiter))]
    return args + ["--out", str(out), "--export", "pc2", "--no-animation", "--no-viewer",
                   *extra]


def progress_lines(chunk: str, pending: str = "") -> tuple[list[str], str]:
    """Split the solver's output (progress bars redraw with ``\\r``) into whole lines and the
    unfinished rest: ``(lines, rest)``."""
    text = pending + chunk
    parts = re.split(r"[\r\n]", text)
    return [p.strip() for p in parts[:-1] if p.strip()], parts[-1]


def read_misses(out) -> list[dict]:
    """The keyframe misses of a finished solve (``summary.json`` in ``out``)."""
    summary = json.loads((Path(out) / "summary.json").read_text())
    return summary["breakdown"]["misses"]


def describe_misses(misses, tolerance: float, start_frame: int = 0) -> list[str]:
    """One line per keyframe: its scene frame, rms and largest miss in mm, hit or missed."""
    lines = []
    for m in misses:
        frame = int(m["term"].rsplit("@", 1)[1]) + start_frame
        rms = m["rms_position_error"]
        lines.append(f"frame {frame}: {1e3 * rms:.1f} mm rms, {1e3 * m['max_position_error']:.1f}"
                     f" mm max: {'hit' if rms <= tolerance else 'MISSED'} (tolerance "
                     f"{1e3 * tolerance:.3g} mm)")
    return lines


def read_pc2(path):
    """``(frames, start, rate)``: ``frames`` a list of per-frame lists of (x, y, z)."""
    data = Path(path).read_bytes()
    magic, version, points, start, rate, samples = _PC2.unpack_from(data)
    if magic != b"POINTCACHE2\0" or version != 1:
        raise ValueError(f"{path} is not a PC2 point cache")
    values = struct.unpack_from(f"<{3 * points * samples}f", data, _PC2.size)
    frames = [[values[3 * (s * points + p): 3 * (s * points + p) + 3] for p in range(points)]
              for s in range(samples)]
    return frames, start, rate


def write_pc2(path, frames, start: float = 0.0, rate: float = 1.0) -> Path:
    """Write ``frames`` (per-frame lists of (x, y, z)) as a PC2 point cache."""
    points = len(frames[0])
    flat = [c for frame in frames for p in frame for c in p]
    Path(path).write_bytes(_PC2.pack(b"POINTCACHE2\0", 1, points, start, rate, len(frames))
                           + struct.pack(f"<{len(flat)}f", *flat))
    return Path(path)


def to_local(frames, world_to_local):
    """Every point of ``frames`` through the 4x4 matrix ``world_to_local`` (row lists): a
    world-space cache made to play on an object with a transform."""
    m = world_to_local
    return [[tuple(m[r][0] * x + m[r][1] * y + m[r][2] * z + m[r][3] for r in range(3))
             for x, y, z in frame] for frame in frames]
