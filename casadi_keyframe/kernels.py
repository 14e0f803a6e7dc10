"""Evaluate a per-interaction CasADi kernel over many interactions, fast.

A kernel is a small SX ``casadi.Function`` whose inputs and outputs are column vectors
describing ONE interaction (a pair of agents, a spring).  :class:`MappedKernel` lifts it
over an index list with ``Function.map`` in fixed-size chunks and evaluates each chunk
through ``Function.buffer`` bound to numpy arrays (no element-by-element conversion); an
input of size k over P interactions is a C-ordered ``(P, k)`` array.  Each chunk function is
compiled once per machine (``gcc -O3``) into a shared library cached in :func:`cache_dir`,
written atomically; with no compiler, no writable cache or ``CASADI_KEYFRAME_JIT=0``,
CasADi's virtual machine gives identical results.  The cache's rules:
``docs/explanations/kernels.md``.
"""
from __future__ import annotations

import functools
import hashlib
import os
import platform
import shutil
import subprocess
import tempfile
import time
import warnings
from pathlib import Path

import casadi as ca
import numpy as np
import scipy.sparse as sp

CHUNKS = (2048, 128)
FLAGS = ("-O3", "-shared", "-fPIC")
_STALE_SECONDS = 600  # a compile folder older than this was left by a killed process
_COMPILED: dict = {}
_JIT_FAILED = False


def cache_dir() -> Path:
    """The folder compiled kernels are kept in (see the module docstring); delete it to clear."""
    explicit = os.environ.get("CASADI_KEYFRAME_CACHE")
    if explicit:
        return Path(explicit).expanduser().absolute()
    xdg = os.environ.get("XDG_CACHE_HOME", "")
    base = Path(xdg) if os.path.isabs(xdg) else Path.home() / ".cache"
    return base / "casadi_keyframe" / "kernels"


def jit_available() -> bool:
    """True when kernels will be compiled (a C compiler exists and compiling is not disabled)."""
    if os.environ.get("CASADI_KEYFRAME_JIT", "1") == "0" or _JIT_FAILED:
        return False
    return shutil.which("gcc") is not None or shutil.which("cc") is not None


@functools.lru_cache(maxsize=None)
def _compiler() -> tuple[str, str]:
    """The C compiler's path and version line: part of every cache key."""
    path = shutil.which("gcc") or shutil.which("cc")
    if path is None:
        raise FileNotFoundError("no C compiler (gcc or cc) on PATH")
    out = subprocess.run([path, "--version"], capture_output=True, text=True, timeout=60)
    return path, out.stdout.partition("\n")[0]


def _remove_stale(folder: Path) -> None:
    """Remove compile folders left in the cache by killed processes."""
    for entry in folder.glob("*.tmp*"):
        try:
            if time.time() - entry.stat().st_mtime > _STALE_SECONDS:
                shutil.rmtree(entry) if entry.is_dir() else entry.unlink()
        except OSError:
            pass  # another process removed it first, or it is not ours to remove


def _compile(code: str, compiler: str, target: Path) -> None:
    """Compile ``code`` into the shared library ``target``, atomically.

    gcc's own intermediate files go to the private folder too (``TMPDIR``), so a process
    killed mid-compile leaves nothing in the system temp folder.
    """
    target.parent.mkdir(parents=True, exist_ok=True)
    _remove_stale(target.parent)
    work = tempfile.mkdtemp(prefix=target.stem + ".tmp", dir=target.parent)
    try:
        out = os.path.join(work, "kernel.so")
        subprocess.run([compiler, *FLAGS, "-x", "c", "-", "-o", out, "-lm"],
                       input=code.encode(), capture_output=True, check=True, cwd=work,
                       env={**os.environ, "TMPDIR": work, "TMP": work, "TEMP": work})
        os.replace(out, target)
    finally:
        shutil.rmtree(work, ignore_errors=True)


def _cached_library(fn: ca.Function) -> ca.Function:
    """``fn`` loaded from its compiled library in the cache, compiling it there if missing."""
    gen = ca.CodeGenerator(fn.name(), {})
    gen.add(fn)
    code = gen.dump()
    compiler, version = _compiler()
    key = "\0".join([code, compiler, version, " ".join(FLAGS), ca.__version__,
                     platform.machine()])
    target = cache_dir() / f"{hashlib.sha256(key.encode()).hexdigest()[:32]}.so"
    if target.exists():
        try:
            return ca.external(fn.name(), str(target))
        except RuntimeError:
            pass  # unloadable (e.g. built elsewhere): compile it again below
    _compile(code, compiler, target)
    return ca.external(fn.name(), str(target))


def _fallback_warning(err: Exception) -> str:
    """Why compiled kernels are unavailable, naming the cache folder and the fixes."""
    folder = cache_dir()
    if isinstance(err, subprocess.CalledProcessError):
        detail = (err.stderr or b"").decode(errors="replace").strip().splitlines()[-3:]
        cause = f"the C compiler failed ({' '.join(detail) or err})"
    else:
        cause = f"{type(err).__name__}: {err}"
    return (f"compiled kernels unavailable in cache folder {folder} ({cause}); using CasADi's "
            "virtual machine instead (same results, slower).  Fix: set CASADI_KEYFRAME_CACHE "
            "to a writable folder and check that gcc works, or set CASADI_KEYFRAME_JIT=0 to "
            "skip compiling without this warning.")


def _mapped_function(kernel: ca.Function, chunk: int, jit: bool) -> ca.Function:
    """The kernel mapped over ``chunk`` interactions, compiled (or loaded) once per process."""
    global _JIT_FAILED
    key = (kernel.serialize(), chunk, jit)
    if key in _COMPILED:
        return _COMPILED[key]
    args = [ca.MX.sym(f"a{i}", kernel.size1_in(i), chunk) for i in range(kernel.n_in())]
    outs = kernel.map(chunk)(*args)
    outs = list(outs) if isinstance(outs, (list, tuple)) else [outs]
    fn = ca.Function(f"{kernel.name()}_x{chunk}", args, outs)
    if jit and not _JIT_FAILED:
        try:
            fn = _cached_library(fn)
        except (OSError, RuntimeError, subprocess.SubprocessError) as err:
            _JIT_FAILED = True  # warn once; every later kernel uses the VM directly
            warnings.warn(_fallback_warning(err), RuntimeWarning, stacklevel=3)
    _COMPILED[key] = fn
    return fn


class _Chunk:
    """One mapped function with its buffer and padded staging arrays."""

    def __init__(self, fn: ca.Function, size: int):
        self.size = size
        self.buf, self.trigger = fn.buffer()
        self.in_stage = [np.zeros((size, fn.size1_in(i))) for i in range(fn.n_in())]
        self.out_stage = [np.zeros((size, fn.size1_out(i))) for i in range(fn.n_out())]

    def run(self, inputs, outputs, lo: int, count: int) -> None:
        """Evaluate interactions ``lo:lo+count`` (``count <= size``), padding when short."""
        full = count == self.size
        for i, a in enumerate(inputs):
            if full:
                self.buf.set_arg(i, memoryview(a[lo:lo + count]))
            else:
                self.in_stage[i][:count] = a[lo:lo + count]
                self.buf.set_arg(i, memoryview(self.in_stage[i]))
        for j, r in enumerate(outputs):
            target = r[lo:lo + count] if full else self.out_stage[j]
            self.buf.set_res(j, memoryview(target))
        self.trigger()
        if not full:
            for j, r in enumerate(outputs):
                r[lo:lo + count] = self.out_stage[j][:count]


def _dense_outputs(kernel: ca.Function) -> ca.Function:
    """``kernel`` with every output dense: a buffer holds an output's nonzeros only, and an
    output that is structurally sparse (a constant damping block, say) would otherwise fill
    the rows of its numpy array in the wrong places."""
    if all(kernel.sparsity_out(j).is_dense() for j in range(kernel.n_out())):
        return kernel
    args = kernel.sx_in()
    outs = kernel.call(args)
    return ca.Function(kernel.name(), args, [ca.densify(o) for o in outs],
                       kernel.name_in(), kernel.name_out())


class MappedKernel:
    """Evaluate ``kernel`` over P interactions given as ``(P, k_i)`` arrays.

    ``MappedKernel(kernel)(a, b, ...)`` returns a list of ``(P, m_j)`` arrays, one per kernel
    output.  Large batches run in chunks of ``CHUNKS[0]``; the remainder in one padded chunk
    (small when it fits), so a call costs few Python round trips and tiny systems stay cheap.
    The mapped functions are compiled (or loaded) at the first call, so a model can hold
    kernels it may never evaluate (tangent kernels, say) at no cost.
    """

    def __init__(self, kernel: ca.Function, *, jit: bool | None = None):
        if kernel.n_in() < 1 or kernel.n_out() < 1:
            raise ValueError("a kernel needs at least one input and one output")
        for i in range(kernel.n_in()):
            if kernel.size2_in(i) != 1:
                raise ValueError(f"kernel input {i} must be a column vector")
        self.kernel = _dense_outputs(kernel)
        self.jit = jit_available() if jit is None else jit
        self._chunks: list[_Chunk] = []
        self.n_out = kernel.n_out()

    def compile(self) -> "MappedKernel":
        """Compile (or load from the cache) now rather than at the first call; returns self."""
        self._compiled()
        return self

    def _compiled(self) -> list[_Chunk]:
        if not self._chunks:
            self._chunks = [_Chunk(_mapped_function(self.kernel, c, self.jit), c) for c in CHUNKS]
        return self._chunks

    def __call__(self, *inputs: np.ndarray) -> list[np.ndarray]:
        if len(inputs) != self.kernel.n_in():
            raise ValueError(f"{self.kernel.name()} takes {self.kernel.n_in()} inputs")
        count = inputs[0].shape[0]
        arrays = []
        for i, a in enumerate(inputs):
            a = np.ascontiguousarray(a, dtype=np.float64)
            if a.shape != (count, self.kernel.size1_in(i)):
                raise ValueError(
                    f"{self.kernel.name()} input {i} must have shape "
                    f"({count}, {self.kernel.size1_in(i)}), got {a.shape}")
            arrays.append(a)
        outputs = [np.empty((count, self.kernel.size1_out(j))) for j in range(self.n_out)]
        chunks = self._compiled()
        big, small = chunks[0], chunks[-1]
        lo = 0
        while lo < count:  # full big chunks, then one padded chunk of the smallest size that fits
            n = min(big.size, count - lo)
            (big if n > small.size else small).run(arrays, outputs, lo, n)
            lo += n
        return outputs


def pair_difference(a: np.ndarray, i: np.ndarray, j: np.ndarray) -> np.ndarray:
    """``a[j] - a[i]`` row by row (``np.take`` gathers rows ~3x faster than indexing)."""
    return np.take(a, j, axis=0) - np.take(a, i, axis=0)


def scatter_pairs(values: np.ndarray, i: np.ndarray, j: np.ndarray, n: int) -> np.ndarray:
    """Add ``values[p]`` to row ``i[p]`` and subtract it from row ``j[p]`` of an ``(n, k)`` array."""
    out = np.empty((n, values.shape[1]))
    for k in range(values.shape[1]):
        col = values[:, k]
        out[:, k] = np.bincount(i, col, minlength=n) - np.bincount(j, col, minlength=n)
    return out


def stencil_values(a: np.ndarray, stencils: np.ndarray) -> np.ndarray:
    """``(P, k m)``: row p holds the rows ``a[stencils[p, 0]], a[stencils[p, 1]], ...`` of an
    ``(n, m)`` array, one after another (a kernel's input over stencils of k particles)."""
    return np.take(a, stencils, axis=0).reshape(stencils.shape[0], -1)


def scatter_stencils(values: np.ndarray, stencils: np.ndarray, n: int) -> np.ndarray:
    """Add each particle's part of ``values`` (``(P, 3 k)``, as :func:`stencil_values`
    lays them out) into its row of an ``(n, 3)`` array."""
    flat, rows = values.reshape(-1, 3), stencils.ravel()
    return np.stack([np.bincount(rows, flat[:, c], minlength=n) for c in range(3)], axis=1)


def stencil_incidence(stencils: np.ndarray, n: int) -> ca.DM:
    """Sparse ``(P k, n)`` matrix with 1 at ``(p k + a, stencils[p, a])``: with
    ``reshape(per_stencil_columns, 3, P k)`` on its left, :func:`scatter_stencils` in CasADi."""
    rows = np.arange(stencils.size)
    return ca.DM(sp.csc_matrix((np.ones(rows.size), (rows, stencils.ravel())),
                               shape=(rows.size, n)))


def pair_incidence(i: np.ndarray, j: np.ndarray, n: int) -> ca.DM:
    """Sparse ``(P, n)`` matrix with +1 at (p, i[p]) and -1 at (p, j[p]).

    ``mtimes(per_pair_columns, pair_incidence(...))`` is :func:`scatter_pairs` symbolically.
    """
    P = i.size
    rows = np.r_[np.arange(P), np.arange(P)]
    return ca.DM(sp.csc_matrix((np.r_[np.ones(P), -np.ones(P)], (rows, np.r_[i, j])),
                               shape=(P, n)))


def interaction_kernels(name: str, x, v, params: list, force, stiffness=None) -> dict[str, ca.Function]:
    """The kernels of one interaction whose force is the SX expression ``force`` in the
    symbols ``x``, ``v``, ``params``, as ``{"force", "jac", "df_dx", "vjp", "jvp"}``:

    * ``force(x, v, *params) -> f``;
    * ``jac(...) -> (vec K, vec D)``, row-major: ``D = df/dv`` and K the stiffness the
      implicit step uses (``stiffness`` when given, e.g. with the destabilising parts clamped
      away, else ``d/dx`` of the force at ``v = 0``, so K stays symmetric);
    * ``df_dx(...) -> vec J``, the full ``df/dx`` (damping included), row-major;
    * ``vjp(x, v, *params, lam, w, q, dt) -> (gx, gv)``: the gradients in x and v of
      ``lam . (dt f + dt^2 K w + dt D q)``, the exact adjoint of a linearized step,
      second derivatives contracted per interaction;
    * ``jvp(x, v, *params, w, q, dt, dx, dv) -> dg``: the same function along ``(dx, dv)``;
    * ``step(x, v, *params, w, q, dt) -> g``: that function itself, the interaction's part
      of a linearized step's right side (the transcription's inverse step is written with
      it, :mod:`casadi_keyframe.optimize.positions`);
    * ``step_jac(x, v, *params, w, q, dt) -> vec dg/d(x, v, w, q)``, row-major: its Jacobian,
      the blocks the transcription's sparse Jacobian is gathered from.
    """
    K = (ca.jacobian(ca.substitute(force, v, ca.SX.zeros(v.shape)), x) if stiffness is None
         else stiffness)
    D, df_dx = ca.jacobian(force, v), ca.jacobian(force, x)
    args = [x, v, *params]
    lam, w, q = (ca.SX.sym(s, force.shape[0]) for s in ("lam", "w", "q"))
    dt = ca.SX.sym("dt")
    g = dt * force + dt ** 2 * ca.mtimes(K, w) + dt * ca.mtimes(D, q)
    phi = ca.dot(lam, g)
    dx, dv = ca.SX.sym("dx", x.shape[0]), ca.SX.sym("dv", v.shape[0])
    return {
        "force": ca.Function(f"{name}", args, [force]),
        "jac": ca.Function(f"{name}_jac", args,
                           [ca.reshape(K.T, -1, 1), ca.reshape(D.T, -1, 1)]),
        "df_dx": ca.Function(f"{name}_df_dx", args, [ca.reshape(df_dx.T, -1, 1)]),
        "vjp": ca.Function(f"{name}_vjp", args + [lam, w, q, dt],
                           [ca.gradient(phi, x), ca.gradient(phi, v)]),
        "jvp": ca.Function(f"{name}_jvp", args + [w, q, dt, dx, dv],
                           [ca.jtimes(g, ca.vertcat(x, v), ca.vertcat(dx, dv))]),
        "step": ca.Function(f"{name}_step", args + [w, q, dt], [g]),
        "step_jac": ca.Function(f"{name}_step_jac", args + [w, q, dt], [ca.reshape(
            ca.jacobian(g, ca.vertcat(x, v, w, q)).T, -1, 1)]),
    }
