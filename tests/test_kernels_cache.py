"""The on-disk cache of compiled kernels: a second process compiles nothing, compiled results
equal the virtual machine's, concurrent and killed runs leave nothing half-written and
nothing in the temp folder, and an unusable cache or compiler falls back to the VM with one
warning.  Every test points CASADI_KEYFRAME_CACHE at its own tmp folder."""
import os
import shutil
import signal
import subprocess
import sys
import time

import casadi as ca
import numpy as np
import pytest

import casadi_keyframe.kernels as kernels
from casadi_keyframe.kernels import MappedKernel, cache_dir
from casadi_keyframe.models.springs import spring_kernels

needs_compiler = pytest.mark.skipif(shutil.which("gcc") is None and shutil.which("cc") is None,
                                    reason="no C compiler")

# A child process: builds cloth kernels with compiling forced on and saves their forces.
# With FORBID set, compiling raises, so the child proves it only loaded from the cache.
CHILD = """
import sys
import numpy as np
import casadi_keyframe.kernels as kernels
from casadi_keyframe.models import ClothModel

def forbidden(*args):
    raise AssertionError("a kernel was compiled although the cache was warm")

if {forbid}:
    kernels._compile = forbidden
model = ClothModel.grid({size}, {size}, jit=True)
assert not kernels._JIT_FAILED, "compiling failed; the VM was used"
x = model.rest_positions + 0.01 * np.random.default_rng(0).standard_normal((model.n, 3))
np.save(sys.argv[1], model.forces(x, np.zeros_like(x)))
"""


def child(tmp_path, cache, out, *, forbid=False, size=4, wait=True):
    """Run (or start, with ``wait=False``) a child with private cache and temp folders."""
    tmp = tmp_path / "tmp"
    tmp.mkdir(exist_ok=True)
    env = {**os.environ, "CASADI_KEYFRAME_CACHE": str(cache), "TMPDIR": str(tmp)}
    env.pop("CASADI_KEYFRAME_JIT", None)
    cmd = [sys.executable, "-c", CHILD.format(forbid=forbid, size=size), str(out)]
    if not wait:
        return subprocess.Popen(cmd, env=env, start_new_session=True)
    done = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    return done


def snapshot(folder):
    """Every file in ``folder`` with its inode and modification time (a rewrite changes both)."""
    return {p.name: (p.stat().st_ino, p.stat().st_mtime_ns) for p in folder.iterdir()}


@pytest.fixture
def fresh(monkeypatch, tmp_path):
    """This process with an empty kernel cache in tmp_path and no memory of compiling."""
    monkeypatch.setenv("CASADI_KEYFRAME_CACHE", str(tmp_path / "cache"))
    monkeypatch.setattr(kernels, "_COMPILED", {})
    monkeypatch.setattr(kernels, "_JIT_FAILED", False)
    return tmp_path / "cache"


def tiny_kernel(name="tiny"):
    x = ca.SX.sym("x", 2)
    return ca.Function(name, [x], [ca.sin(x) * x[0]])


def test_cache_dir_follows_the_environment(monkeypatch, tmp_path):
    monkeypatch.setenv("CASADI_KEYFRAME_CACHE", str(tmp_path / "mine"))
    assert cache_dir() == tmp_path / "mine"
    monkeypatch.delenv("CASADI_KEYFRAME_CACHE")
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert cache_dir() == tmp_path / "xdg" / "casadi_keyframe" / "kernels"
    monkeypatch.delenv("XDG_CACHE_HOME")
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    assert cache_dir() == tmp_path / "home" / ".cache" / "casadi_keyframe" / "kernels"


@needs_compiler
def test_second_process_loads_every_kernel_from_the_cache(tmp_path):
    cache = tmp_path / "cache"
    child(tmp_path, cache, tmp_path / "cold.npy")
    cold = snapshot(cache)
    assert cold and all(name.endswith(".so") for name in cold), cold  # no compile folder left
    child(tmp_path, cache, tmp_path / "warm.npy", forbid=True)
    assert snapshot(cache) == cold
    np.testing.assert_array_equal(np.load(tmp_path / "warm.npy"), np.load(tmp_path / "cold.npy"))
    assert not os.listdir(tmp_path / "tmp")


@needs_compiler
def test_concurrent_processes_compiling_the_same_kernels_agree(tmp_path):
    cache = tmp_path / "cache"
    procs = [child(tmp_path, cache, tmp_path / f"{k}.npy", wait=False) for k in range(2)]
    assert [p.wait(timeout=300) for p in procs] == [0, 0]
    assert all(name.endswith(".so") for name in os.listdir(cache))
    np.testing.assert_array_equal(np.load(tmp_path / "0.npy"), np.load(tmp_path / "1.npy"))
    child(tmp_path, cache, tmp_path / "warm.npy", forbid=True)


@needs_compiler
def test_compiled_kernels_equal_the_virtual_machine(fresh):
    rng = np.random.default_rng(3)
    for kernel in spring_kernels(1e-6).values():
        inputs = [rng.standard_normal((2100, kernel.size1_in(i))) for i in range(kernel.n_in())]
        inputs[2] = 1 + np.abs(inputs[2])  # positive rest lengths
        vm = MappedKernel(kernel, jit=False)
        compiled = MappedKernel(kernel, jit=True)
        loaded = kernels._mapped_function(kernel, kernels.CHUNKS[0], True)
        assert loaded.class_name() == "External"
        for a, b in zip(compiled(*inputs), vm(*inputs)):
            np.testing.assert_allclose(a, b, rtol=1e-13, atol=1e-13)


@needs_compiler
def test_killed_run_leaves_nothing_in_the_temp_folder(tmp_path):
    cache = tmp_path / "cache"
    proc = child(tmp_path, cache, tmp_path / "killed.npy", size=6, wait=False)
    deadline = time.monotonic() + 120
    while not any(".tmp" in name for name in (os.listdir(cache) if cache.exists() else [])):
        assert proc.poll() is None, "the child finished before a compile could be interrupted"
        assert time.monotonic() < deadline, "no compile started within two minutes"
        time.sleep(0.005)
    os.killpg(proc.pid, signal.SIGKILL)  # the child and its compiler, mid-compile
    proc.wait()
    assert not os.listdir(tmp_path / "tmp")
    child(tmp_path, cache, tmp_path / "after.npy", size=6)  # the half-done compile is not used
    assert not os.listdir(tmp_path / "tmp")


@needs_compiler
def test_compile_folders_of_killed_runs_are_removed_when_stale(fresh):
    fresh.mkdir()
    old, new = fresh / "abc.tmp_old", fresh / "abc.tmp_new"
    for folder in (old, new):
        folder.mkdir()
        (folder / "kernel.so").write_bytes(b"half")
    os.utime(old, (time.time() - 2 * kernels._STALE_SECONDS,) * 2)
    MappedKernel(tiny_kernel(), jit=True).compile()
    assert not old.exists() and new.exists()


@needs_compiler
def test_unloadable_library_in_the_cache_is_compiled_again(fresh, monkeypatch, tmp_path):
    MappedKernel(tiny_kernel(), jit=True).compile()
    other = tmp_path / "other"
    other.mkdir()
    for name in os.listdir(fresh):
        (other / name).write_bytes(b"not a shared library")
    monkeypatch.setenv("CASADI_KEYFRAME_CACHE", str(other))
    monkeypatch.setattr(kernels, "_COMPILED", {})
    x = np.random.default_rng(1).standard_normal((50, 2))
    np.testing.assert_array_equal(MappedKernel(tiny_kernel(), jit=True)(x)[0],
                                  MappedKernel(tiny_kernel(), jit=False)(x)[0])
    assert not kernels._JIT_FAILED
    assert all((other / name).stat().st_size > 1000 for name in os.listdir(other))


def test_unwritable_cache_folder_falls_back_to_the_vm_with_one_warning(fresh, monkeypatch,
                                                                        tmp_path):
    blocker = tmp_path / "a_file"
    blocker.write_text("not a folder")
    monkeypatch.setenv("CASADI_KEYFRAME_CACHE", str(blocker / "cache"))
    x = np.random.default_rng(0).standard_normal((300, 2))
    with pytest.warns(RuntimeWarning, match="CASADI_KEYFRAME_CACHE") as record:
        fallback = MappedKernel(tiny_kernel(), jit=True).compile()
        MappedKernel(tiny_kernel("other"), jit=True).compile()
    assert len(record) == 1 and str(blocker / "cache") in str(record[0].message)
    assert not kernels.jit_available()
    np.testing.assert_array_equal(fallback(x)[0], MappedKernel(tiny_kernel(), jit=False)(x)[0])


@needs_compiler
def test_failed_compile_falls_back_and_leaves_no_compile_folder(fresh, monkeypatch):
    monkeypatch.setattr(kernels, "FLAGS", ("-O3", "--no-such-flag"))
    with pytest.warns(RuntimeWarning, match="compiler failed"):
        MappedKernel(tiny_kernel(), jit=True).compile()
    assert os.listdir(fresh) == []
