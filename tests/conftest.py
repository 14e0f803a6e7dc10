"""Pytest hooks and fixtures; shared helpers live in ``helpers.py``."""
import os

import pytest


def pytest_configure(config):
    """Compiled kernels go to pytest's own cache (``.pytest_cache/d/casadi_keyframe_kernels``),
    not the user's: the suite leaves the home folder alone, yet later runs and the suite's
    subprocesses (CLI, notebooks) load them instead of compiling again, and
    ``pytest --cache-clear`` clears them.  An explicit CASADI_KEYFRAME_CACHE is kept."""
    if "CASADI_KEYFRAME_CACHE" not in os.environ and getattr(config, "cache", None) is not None:
        os.environ["CASADI_KEYFRAME_CACHE"] = str(config.cache.mkdir("casadi_keyframe_kernels"))


def pytest_terminal_summary(terminalreporter):
    """The slow suite's table of full-size figures (``make test-slow``), when it ran."""
    import sys

    from casadi_keyframe.optimize.report import format_misses
    module = sys.modules.get("test_slow_figures") or sys.modules.get("tests.test_slow_figures")
    rows = getattr(module, "TABLE", [])
    if not rows:
        return
    write = terminalreporter.write_line
    write("")
    write("figure         controls  iterations  CPU s  misses")
    for r in rows:
        write(f"{r['figure']:14s} {r['size']:8d}  {r['iterations']:10d}  {r['cpu_seconds']:5.0f}  "
              f"{format_misses(r['misses'])}")
        write(f"{'':14s} {r['message']}")


@pytest.fixture(params=["smooth", "hard"])
def cutoff(request):
    return request.param
