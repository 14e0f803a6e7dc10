"""One run per results folder: :func:`locked` holds a lock file in the folder (the holder's
process id, host and command) while a run writes there, so a second run into the same
``--out`` is refused by name, with the holder's pid, instead of mixing the two runs' files.
A lock whose holder is gone (a killed run) is taken over."""
from __future__ import annotations

import contextlib
import json
import os
import socket
import sys
import time
from pathlib import Path

LOCK = ".casadi-keyframe.lock"
_held: dict = {}  # folder -> times this process entered it


class FolderInUse(ValueError):
    """The folder holds a live run's lock."""


@contextlib.contextmanager
def locked(folder, option: str = "--out"):
    """Hold ``folder``'s lock for the block (entered again by the same process: shared);
    :class:`FolderInUse` (a ValueError naming ``option``) when another live process holds
    it.  Yields the folder."""
    folder = Path(folder).resolve()
    if folder in _held:
        _held[folder] += 1
        try:
            yield folder
        finally:
            _held[folder] -= 1
        return
    path = folder / LOCK
    _take(path, option)
    _held[folder] = 1
    try:
        yield folder
    finally:
        del _held[folder]
        with contextlib.suppress(OSError):
            if _holder(path).get("pid") == os.getpid():
                path.unlink()


def _take(path: Path, option: str) -> None:
    """Create the lock file, or refuse: a live holder keeps it, a dead one's is replaced."""
    mine = json.dumps({"pid": os.getpid(), "host": socket.gethostname(),
                       "started": time.strftime("%Y-%m-%d %H:%M:%S"),
                       "command": " ".join(sys.argv[:1] + sys.argv[1:])[:300]})
    for _ in range(3):
        try:
            with open(path, "x") as f:  # exclusive: one of two racing runs wins
                f.write(mine)
            return
        except FileExistsError:
            holder = _holder(path)
            if _alive(holder):
                host = f" on {holder['host']}" if holder.get("host") else ""
                began = f", started {holder['started']}" if holder.get("started") else ""
                raise FolderInUse(
                    f"{option} {path.parent} is in use by another run (pid {holder['pid']}"
                    f"{host}{began}): wait for it to end, stop it, or give another "
                    f"{option}") from None
            with contextlib.suppress(OSError):
                path.unlink()  # its holder is gone (a run killed): take it over
    raise FolderInUse(f"{option} {path.parent}: could not take its lock ({path.name}); "
                      f"give another {option}")


def _holder(path: Path) -> dict:
    try:
        found = json.loads(path.read_text())
        return found if isinstance(found, dict) else {}
    except (OSError, ValueError):
        return {}


def _alive(holder: dict) -> bool:
    """Whether the lock's holder still runs (a lock from another host is taken as live;
    one that cannot be read as dead)."""
    pid = holder.get("pid")
    if not isinstance(pid, int) or pid <= 0:
        return False
    if holder.get("host") not in (None, socket.gethostname()):
        return True
    if pid == os.getpid():
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # another user's live process
        return True
    return True
