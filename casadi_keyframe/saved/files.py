"""Files at the library's edge, each written whole or not at all and read back checked.

Every file is written to a temporary name in the same folder, then moved onto its name with
:func:`os.replace` (:func:`atomic_path`), so an interrupted or killed run never leaves a
half-written file, only the previous version or none.  :func:`read_npz` and
:func:`read_json` are the one way the library reads its own files: an ``.npz`` is read with
``allow_pickle=False`` (unpickling runs whatever code the file holds), and any damage is a
:class:`FileDamaged` naming the file, what is wrong and what to do.  :func:`writable_folder`
and :func:`writable_file` check an output path by writing a scratch file there, so a path
that cannot be written is refused by the option's name before any work starts.
"""
from __future__ import annotations

import contextlib
import json
import os
import tempfile
import zipfile
import zlib
from pathlib import Path

import numpy as np

from ..interrupts import deferred

ZIP_MAGIC, NPY_MAGIC = b"PK\x03\x04", b"\x93NUMPY"


class FileDamaged(ValueError):
    """A file the library reads that is missing what it needs or is not what it should be;
    the message names the file, what is wrong and what to do."""

    def __init__(self, path, problem: str, fix: str):
        super().__init__(f"{path} {problem}; {fix}")
        self.path, self.problem, self.fix = Path(path), problem, fix


def read_npz(path, *, required=(), fix: str = "write it again") -> dict[str, np.ndarray]:
    """Every array of the ``.npz`` at ``path``, read without unpickling anything.

    ``required`` names arrays the file must hold; ``fix`` says what to do if the file is
    damaged (it ends the message).  A missing file is a FileNotFoundError; anything else
    wrong is a :class:`FileDamaged`."""
    path = Path(path)
    head = _head(path, fix)
    if head.startswith(NPY_MAGIC):
        raise FileDamaged(path, "is a single numpy array (.npy), not an .npz archive of named "
                                "arrays", fix)
    if not head.startswith(ZIP_MAGIC):
        raise FileDamaged(path, "is not an npz file (an npz is a zip archive of arrays; this "
                                "one starts with other bytes)", fix)
    try:
        archive = np.load(path, allow_pickle=False)
    except (zipfile.BadZipFile, EOFError, OSError, ValueError):
        raise FileDamaged(path, "is truncated: its zip directory is missing (the file was cut "
                                "short: a full disk, an interrupted copy)", fix) from None
    arrays = {}
    with archive:
        odd = [n for n in archive.zip.namelist() if not n.endswith(".npy")]
        if odd:
            raise FileDamaged(path, f"is a zip archive but not an npz: its member {odd[0]!r} "
                                    "is not a numpy array", fix)
        for name in archive.files:
            arrays[name] = _member(archive, name, path, fix)
    missing = [name for name in required if name not in arrays]
    if missing:
        raise FileDamaged(path, f"is missing array{'s' * (len(missing) > 1)} "
                                f"{', '.join(repr(m) for m in missing)} (it holds "
                                f"{', '.join(arrays) or 'none'})", fix)
    return arrays


def _head(path: Path, fix: str) -> bytes:
    """The file's first bytes; FileNotFoundError if it is missing, FileDamaged if it is a
    folder, unreadable or empty."""
    if not path.exists():
        raise FileNotFoundError(f"{path} does not exist")
    if path.is_dir():
        raise FileDamaged(path, "is a folder, not a file", fix)
    try:
        with open(path, "rb") as f:
            head = f.read(8)
    except OSError as err:
        raise FileDamaged(path, f"cannot be read ({err.strerror or err})", fix) from None
    if not head:
        raise FileDamaged(path, "is empty (0 bytes)", fix)
    return head


def _member(archive, name: str, path: Path, fix: str) -> np.ndarray:
    """One array of an open npz, its damage named."""
    try:
        return archive[name]
    except ValueError as err:
        if "pickle" in str(err).lower() or "object" in str(err).lower():
            raise FileDamaged(path, f"holds Python objects in array {name!r}, which this "
                                    "library never writes and will not load (loading them "
                                    "could run code from the file)", fix) from None
        raise FileDamaged(path, f"has a damaged array {name!r} ({_one_line(err)})", fix) from None
    except (zipfile.BadZipFile, zlib.error, EOFError, OSError) as err:
        raise FileDamaged(path, f"has a damaged array {name!r} ({_one_line(err)}): the file "
                                "was altered or cut short", fix) from None


def read_json(path, *, fix: str = "write it again") -> object:
    """The JSON value in the file at ``path``; FileNotFoundError if it is missing,
    :class:`FileDamaged` if it is empty, not text or not JSON."""
    path = Path(path)
    _head(path, fix)
    try:
        text = path.read_text(encoding="utf-8")
    except UnicodeDecodeError:
        raise FileDamaged(path, "is not a text file (JSON is UTF-8 text)", fix) from None
    try:
        return json.loads(text)
    except json.JSONDecodeError as err:
        cut = err.pos >= len(text.rstrip()) or err.msg.startswith("Unterminated string")
        raise FileDamaged(path, ("is truncated (its JSON ends early)" if cut else
                                 f"is not valid JSON ({err.msg} at line {err.lineno})"),
                          fix) from None


def writable_folder(folder, option: str, *, fix: str | None = None) -> Path:
    """``folder`` created (with its parents) and checked writable by writing a scratch file
    in it; a ValueError naming ``option`` (``"--out"``, ``"out="``) and ending with ``fix``
    (default: choose another ``option``) otherwise."""
    fix = fix or f"choose another {option}"
    if not str(folder).strip():
        raise ValueError(f"{option} is empty: give a folder to write to")
    out = Path(folder)
    try:
        out.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryFile(dir=out):
            pass
    except OSError as err:
        raise ValueError(f"cannot write the output folder {out} ({option}): "
                         f"{_reason(out, err)}; {fix}") from None
    return out


def writable_file(path, option: str) -> Path:
    """``path`` checked as a file to write (its folder created, a scratch file written
    beside it; not a folder itself); a ValueError naming ``option`` otherwise."""
    path = Path(path)
    if not str(path).strip() or path.name in ("", ".", ".."):
        raise ValueError(f"{option} {str(path)!r} is not a file name: give a path such as "
                         "runs/best.npz")
    if path.is_dir():
        raise ValueError(f"{option} {path} is a folder: give a file path inside it, such as "
                         f"{path / 'checkpoint.npz'}")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryFile(dir=path.parent):
            pass
        if path.exists() and not os.access(path, os.W_OK):
            raise PermissionError(13, "the file is read-only")
    except OSError as err:
        raise ValueError(f"cannot write {path} ({option}): {_reason(path.parent, err)}; "
                         f"choose another path") from None
    return path


def _reason(folder: Path, err: OSError) -> str:
    """Why ``folder`` cannot be written, in words: a file in its way, or the system's
    reason (permission denied, read-only file system, no such folder...)."""
    blocker = next((p for p in (folder, *folder.parents) if p.exists() and not p.is_dir()),
                   None)
    if blocker is not None:
        return f"{blocker} is a file, not a folder"
    return err.strerror or str(err)


def _one_line(err) -> str:
    return " ".join(str(err).split())


@contextlib.contextmanager
def atomic_path(path):
    """Yield a temporary path beside ``path`` (same suffix, so writers pick the format) to
    write to; it replaces ``path`` when the block ends normally and is deleted otherwise
    (an exception, Ctrl-C)."""
    path = Path(path)
    tmp = path.with_name(f".{path.stem}.{os.getpid()}.tmp{path.suffix}")
    try:
        yield tmp
        with deferred():
            os.replace(tmp, path)
    finally:
        with deferred():
            tmp.unlink(missing_ok=True)


def write_npz(path, *, compressed: bool = False, **arrays) -> Path:
    """``np.savez`` (or ``savez_compressed``) through :func:`atomic_path`."""
    with atomic_path(path) as tmp, open(tmp, "wb") as f:
        (np.savez_compressed if compressed else np.savez)(f, **arrays)
    return Path(path)


def write_json(path, obj) -> Path:
    """Indented JSON (numpy scalars and arrays allowed) through :func:`atomic_path`."""
    text = json.dumps(obj, indent=2, default=as_json)
    with atomic_path(path) as tmp:
        tmp.write_text(text)
    return Path(path)


def as_json(obj):
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, Path):
        return str(obj)
    raise TypeError(f"cannot write {type(obj).__name__} to JSON")
