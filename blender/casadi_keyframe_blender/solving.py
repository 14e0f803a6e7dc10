"""A solve in its subprocess, watched from Blender (its progress lines, cancelled by a
SIGINT that makes the solver write its best point and stop), and its result put on the cloth
as a Mesh Cache modifier that plays it in the object's own space frame by frame."""
from __future__ import annotations

import os
import queue
import signal
import subprocess
import threading
import time
from pathlib import Path

import bpy

from . import bridge
from .collect import DEFORMERS, MODIFIER

RESULT = "casadi_keyframe_result"  # the cloth's property naming its last result folder
STOPPED = (0, 1, 3, 130, 143)  # exit codes that leave a result (see casadi-keyframe solve --help)


class SolveProcess:
    """``casadi-keyframe`` running ``command``: its output read on a thread (whole lines
    from :meth:`drain`), its latest progress line and when it came (:meth:`status`);
    :meth:`cancel` sends SIGINT, on which the solver keeps its best point, writes its
    result and exits."""

    def __init__(self, command: list[str]):
        self.process = subprocess.Popen(command, stdout=subprocess.PIPE,
                                        stderr=subprocess.STDOUT, text=True, bufsize=1,
                                        env={**os.environ, "PYTHONUNBUFFERED": "1"})
        self.chunks, self.pending = queue.Queue(), ""
        self.last, self.last_at, self.cancelled_at = "starting", time.monotonic(), None
        self.closed = False  # the solver's output has ended
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self):
        for chunk in iter(lambda: self.process.stdout.read(256), ""):
            self.chunks.put(chunk)
        self.chunks.put(None)  # the output is closed

    def drain(self, wait: float = 0.0) -> list[str]:
        """The whole lines printed since the last call (waiting up to ``wait`` s for one)."""
        lines = []
        while True:
            try:
                chunk = self.chunks.get(timeout=wait) if wait and not lines else \
                    self.chunks.get_nowait()
            except queue.Empty:
                break
            if chunk is None:
                chunk, self.closed = "\n", True
            new, self.pending = bridge.progress_lines(chunk, self.pending)
            lines += new
        if lines:
            self.last, self.last_at = lines[-1], time.monotonic()
        return lines

    @property
    def running(self) -> bool:
        """Whether the solver still writes (its output is still open)."""
        return not self.closed

    def status(self) -> str:
        """The status bar's text: the time left counted down since the last line came."""
        text = bridge.status_text(self.last, time.monotonic() - self.last_at)
        return ("stopping: keeping the best point | " if self.cancelled_at else "") + text

    def cancel(self) -> None:
        """Ask the solver to stop (SIGINT): it writes its best point and exits."""
        if self.cancelled_at is None and self.process.poll() is None:
            self.cancelled_at = time.monotonic()
            self.process.send_signal(signal.SIGINT)

    def wait(self) -> int:
        """Wait for the end, reading the rest of the output; the exit code."""
        while self.running:
            for line in self.drain(wait=0.2):
                print("casadi-keyframe:", line)
        return self.process.wait()


def result_frames(out: Path) -> list:
    """The result's positions per frame (world space, from ``result.npz``, which a solve
    stopped by a signal writes too; Blender bundles numpy)."""
    import numpy as np

    with np.load(out / "result.npz", allow_pickle=False) as data:
        return data["x"].tolist()


def frame_transforms(obj, scene, count: int) -> list:
    """World-to-local 4x4 matrices (row lists) of ``obj`` at the ``count`` frames from the
    scene's start (a cloth parented to a moving rig has one per frame)."""
    current = scene.frame_current
    try:
        out = []
        for k in range(count):
            scene.frame_set(scene.frame_start + k)
            out.append([list(row) for row in obj.matrix_world.inverted()])
        return out
    finally:
        scene.frame_set(current)


def install_cache(obj, path: Path, frame_start: int):
    """The Mesh Cache modifier playing ``path`` on ``obj`` from ``frame_start``, one cache
    frame per scene frame, placed after the deforming modifiers (an armature's result is
    replaced by the cache, which already follows it) and before those that add geometry."""
    mod = obj.modifiers.get(MODIFIER) or obj.modifiers.new(MODIFIER, "MESH_CACHE")
    mod.cache_format, mod.filepath = "PC2", str(path)
    mod.frame_start = frame_start
    mod.time_mode, mod.play_mode, mod.frame_scale = "FRAME", "SCENE", 1.0
    mod.forward_axis, mod.up_axis = "POS_Y", "POS_Z"
    others = [m for m in obj.modifiers if m != mod]
    place = 0
    while place < len(others) and others[place].type in DEFORMERS:
        place += 1
    obj.modifiers.move(list(obj.modifiers).index(mod), place)
    return mod


def finish(context, obj, out: Path, code: int) -> list[str]:
    """Read the misses, put the cache on ``obj`` and return the lines to show."""
    scene, settings = context.scene, context.scene.casadi_keyframe
    if code not in STOPPED or not (out / "summary.json").is_file():
        raise RuntimeError(f"casadi-keyframe failed (exit code {code}): see the console")
    lines = bridge.describe_misses(bridge.read_misses(out), settings.tolerance,
                                   scene.frame_start)
    frames = result_frames(out)
    local = bridge.write_pc2(out / f"{bpy.path.clean_name(obj.name)}_local.pc2",
                             bridge.to_local(frames, frame_transforms(obj, scene, len(frames))))
    install_cache(obj, local, scene.frame_start)
    scene.frame_end = max(scene.frame_end, scene.frame_start + len(frames) - 1)
    settings.misses = "; ".join(lines)
    obj[RESULT] = str(out)
    return lines
