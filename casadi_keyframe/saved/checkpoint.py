"""Where a search keeps its best controls on disk (:class:`Checkpoint`), written atomically
at every iteration, with what rebuilds its problem."""
from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np

from .files import as_json, writable_file, write_npz


class Checkpoint:
    """Where a search keeps its best controls: ``write(u, standing, final=, stage=, ...)``
    replaces the file with ``u`` (on the final grid), its standing's objective (``fun``) and
    whether it meets the goal (``goal_met``), those fields and ``meta`` (what rebuilds the
    problem: ``problem``, ``problem_file``, ``overrides``; the method...), but only with a
    point at least as good as the one it holds (:meth:`better`), so a checkpoint never gets
    worse.  :meth:`with_meta` gives one with more metadata that shares that rule; its
    ``generation`` (a later round of hard keyframes) ranks above earlier ones.

    A standing is the solve's ranking of a point (``optimize.kept.Standing``: ``met``,
    ``objective``, ``at_least(other)``): the checkpoint asks it, it does not rank points of
    its own."""

    def __init__(self, path, **meta):
        self.path, self.meta = Path(path), meta
        self.generation = 0
        self._held = {}  # the key of the point on disk, shared by with_meta's copies

    def with_meta(self, generation: int | None = None, **more) -> "Checkpoint":
        out = Checkpoint(self.path, **{**self.meta, **more})
        out._held = self._held
        out.generation = self.generation if generation is None else int(generation)
        return out

    @staticmethod
    def better(new: tuple, old: tuple | None) -> bool:
        """Whether a point keyed ``(final, generation, stage, standing)`` replaces ``old``: a
        point of the final problem beats any of a coarser stage; a later generation beats an
        earlier one that it meets the goal as well as; otherwise the standing at least as
        good; before the final problem a later stage wins (its objective is at another time
        step or mesh)."""
        if old is None:
            return True
        final, generation, stage, standing = new
        if final != old[0]:
            return final
        if generation != old[1]:
            return generation > old[1] and standing.met >= old[3].met
        if not final and stage != old[2]:
            return stage > old[2]
        return standing.at_least(old[3])

    def write(self, u, standing, *, final: bool = True, stage: int = 0, **fields) -> bool:
        """Write ``u`` if it is at least as good as the point held (see :meth:`better`);
        whether it was written."""
        key = (bool(final), self.generation, int(stage), standing)
        if not self.better(key, self._held.get("key")):
            return False
        fields = {"fun": float(standing.objective), "goal_met": bool(standing.met),
                  "stage": key[2], **fields}
        meta = json.dumps({**self.meta, **fields}, default=as_json)
        write_npz(self.path, u=np.asarray(u, dtype=float), meta=np.array(meta), **fields)
        self._held["key"] = key
        return True


def as_checkpoint(checkpoint) -> Checkpoint | None:
    """None, a :class:`Checkpoint`, or a path made into one; its path checked writable
    (ValueError naming ``checkpoint=``) before a search starts, not at its first
    iteration."""
    if checkpoint is None:
        return None
    if not isinstance(checkpoint, Checkpoint):
        if not isinstance(checkpoint, (str, os.PathLike)):
            raise TypeError(f"checkpoint= is a file path (or a Checkpoint), got "
                            f"{type(checkpoint).__name__}")
        checkpoint = Checkpoint(checkpoint)
    writable_file(checkpoint.path, "checkpoint=")
    return checkpoint
