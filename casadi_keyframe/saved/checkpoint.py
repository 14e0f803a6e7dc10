"""Where a search keeps its best controls on disk (:class:`Checkpoint`), written atomically
at every iteration, with what rebuilds its problem."""
from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np

from .files import as_json, writable_file, write_npz


class Checkpoint:
    """Where a search keeps its best controls: ``write(u, fun=, nit=, stage=, stage_dt=)``
    replaces the file with ``u`` (on the final grid), those fields and ``meta`` (what
    rebuilds the problem: ``problem``, ``problem_file``, ``overrides``; the method...)."""

    def __init__(self, path, **meta):
        self.path, self.meta = Path(path), meta

    def write(self, u, **fields) -> None:
        meta = json.dumps({**self.meta, **fields}, default=as_json)
        write_npz(self.path, u=np.asarray(u, dtype=float), meta=np.array(meta), **fields)


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
