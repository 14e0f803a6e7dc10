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
    return write_motion(folder, name, frames, polygons)


def write_motion(folder, name: str, frames, polygons) -> Path:
    """A time-sampled mesh for the solver (a moving collider, or the cloth whose pinned
    vertices follow it): the point cache ``NAME.pc2``, one sample per scene frame from the
    start, beside its rest mesh ``NAME_rest.obj`` (the first sample)."""
    folder = Path(folder)
    (folder / f"{name}_rest.obj").write_text(
        obj_text(frames[0], polygons, f"{name} at the start, world space"))
    return write_pc2(folder / f"{name}.pc2", frames)


def pins_move(frames, pins, tolerance: float = 1e-6) -> bool:
    """Whether any vertex of ``pins`` in ``frames`` (per-frame lists of (x, y, z)) leaves
    its first place by more than ``tolerance`` metres (float32 files hold about 1e-7 m)."""
    first = frames[0]
    return any(max(abs(a - b) for a, b in zip(frame[i], first[i])) > tolerance
               for frame in frames[1:] for i in pins)


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
                  maxiter: int | None = None, bodies=(), pin_motion=None, resume=None,
                  from_frame: int | None = None, extra=()) -> list[str]:
    """The ``casadi-keyframe solve mesh_keyframes`` command line: ``targets`` is a list of
    ``(frame, file)``, ``bodies`` the colliders' mesh files (:func:`write_body`),
    ``pin_motion`` the cloth's own time-sampled mesh that the ``pins`` follow
    (:func:`write_motion`; None: they stay where they are); ``resume`` a finished run's
    folder whose motion up to result frame ``from_frame`` is kept (the rest solved again);
    the result is also exported as a PC2 point cache."""
    keyframes = ",".join(f"{frame}:{path}" for frame, path in sorted(targets))
    args = [str(executable), "solve", PROBLEM, "--set", f"cloth={cloth}", "--set",
            f"keyframes={keyframes}", "--set", f"dt={dt}", "--set", f"steps={int(steps)}"]
    if pins:
        args += ["--set", "pins=" + ",".join(str(int(i)) for i in sorted(pins)) + ","]
    if bodies:
        args += ["--set", "bodies=" + ",".join(str(b) for b in bodies)]
    if pin_motion is not None:
        args += ["--set", f"pin_motion={pin_motion}"]
    if resume is not None:
        args += ["--resume", str(resume), "--from-frame", str(int(from_frame))]
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


_LEFT = re.compile(r"(?P<kind>about|at most) (?P<time>\d+ (?:h|min|s)(?: \d+ (?:h|min|s))*) left")
_UNITS = {"h": 3600, "min": 60, "s": 1}


def time_left(line: str):
    """``("about" or "at most", seconds)`` from a progress line's ``..., about 1 min 20 s
    left`` (see ``casadi_keyframe.progress.status``), or None when it names none."""
    match = _LEFT.search(line)
    if not match:
        return None
    parts = match["time"].split()
    return match["kind"], float(sum(int(n) * _UNITS[u] for n, u in zip(parts[::2], parts[1::2])))


def format_seconds(seconds: float) -> str:
    """``"45 s"``, ``"3 min 20 s"``, ``"1 h 5 min"`` (as the library's progress lines)."""
    seconds = max(float(seconds), 0.0)
    if seconds < 90:
        return f"{seconds:.0f} s"
    if seconds < 3600:
        return f"{int(seconds // 60)} min {int(seconds % 60)} s"
    return f"{int(seconds // 3600)} h {int(seconds % 3600 // 60)} min"


def status_text(line: str, age: float) -> str:
    """The status bar's text for the solver's last progress ``line``, shown ``age``
    seconds after it came (the solver writes one every few seconds into a pipe): its time
    left counted down meanwhile and put first, then the line."""
    left = time_left(line)
    if left is None:
        return line
    return f"{left[0]} {format_seconds(left[1] - age)} left | {line}"


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
    """Every point of ``frames`` through the 4x4 matrix ``world_to_local`` (row lists; or
    one such matrix per frame, for an object that moves): a world-space cache made to play
    on an object with a transform."""
    per_frame = (world_to_local if isinstance(world_to_local[0][0], (list, tuple))
                 else [world_to_local] * len(frames))
    if len(per_frame) < len(frames):
        raise ValueError(f"{len(per_frame)} transforms for {len(frames)} frames")
    return [[tuple(m[r][0] * x + m[r][1] * y + m[r][2] * z + m[r][3] for r in range(3))
             for x, y, z in frame] for frame, m in zip(frames, per_frame)]
