"""Every stage stops at its own next check, for a signal or for the time limit (issue 42):
the search, its first evaluation, multiple shooting (its rounds here and its workers), a
homotopy level, the finish, a long simulation, the start of a command-line run and the
drawing.  Each stop is sent from inside the stage (at a step of its progress), by a real
SIGINT to this process or by a clock that passes when told; the test counts the steps the
stage makes after it (none) and checks what the stage kept and said.  No wall time is
asserted: a loaded machine is slower, not wrong."""
import multiprocessing
import os
import signal
import threading

import numpy as np
import pytest
from helpers import Clock
from test_augmented_lagrangian import swing
from test_finish import tight
from test_kept import shifted
from test_shooting import sheet_problem

from casadi_keyframe import load_problem, progress
from casadi_keyframe.cli import main
from casadi_keyframe.interrupts import Interrupted, OutOfTime, catching, limited
from casadi_keyframe.optimize import solve
from casadi_keyframe.optimize.outcome import INTERRUPTED, LIMIT


class StopIn:
    """Sends ``stop()`` at the ``at``-th step of progress made while a task whose label
    holds ``label`` is under way (``iterations``: counting the stage's iterations only),
    then counts the steps made there after it (:attr:`after`)."""

    def __init__(self, monkeypatch, label, at, stop, iterations=False):
        real, self.seen, self.after, self.sent = progress.advance, 0, 0, False

        def advance(count=1, facts=None):
            real(count, facts)
            if not any(label in t.label for t in progress._tasks):
                return
            if self.sent:
                self.after += 1
            elif facts is not None or not iterations:
                self.seen += 1
                if self.seen >= at:
                    self.sent = True
                    stop()

        monkeypatch.setattr(progress, "advance", advance)


def sigint():
    os.kill(os.getpid(), signal.SIGINT)  # caught by catching(): raised at the next check


@pytest.fixture(scope="module")
def flock():
    return load_problem("flock_path", agents=6, steps=20, tolerance=2.0)


@pytest.mark.parametrize("kind", ["signal", "time"])
def test_the_search_stops_at_its_next_step(flock, kind, monkeypatch):
    clock = Clock()
    stop = StopIn(monkeypatch, "[lbfgsb]", 200, sigint if kind == "signal" else clock.end)
    with catching():
        r = solve(flock, maxiter=200, quiet=True, stop="method", deadline=clock)
    assert stop.sent and stop.after == 0
    assert r.status == (INTERRUPTED if kind == "signal" else LIMIT), r.message
    assert r.nit >= 1 and r.fun <= flock.objective(flock.initial_controls())


@pytest.mark.parametrize("kind", ["signal", "time"])
def test_the_first_evaluation_stops_inside_its_simulations(flock, kind, monkeypatch):
    """Finite differences: the first evaluation is hundreds of simulations; it stops in
    the third step of the first and the start is the result."""
    clock = Clock()
    stop = StopIn(monkeypatch, "[lbfgsb]", 3, sigint if kind == "signal" else clock.end)
    with catching():
        r = solve(flock, maxiter=5, quiet=True, gradient="fd", deadline=clock)
    assert stop.sent and stop.after == 0
    assert r.status == (INTERRUPTED if kind == "signal" else LIMIT)
    assert "during the first evaluation" in r.message and r.nfev == 0
    np.testing.assert_array_equal(r.x, flock.initial_controls())


@pytest.mark.parametrize("kind", ["signal", "time"])
def test_a_homotopy_level_stops_and_the_stages_after_it_say_why(flock, kind, monkeypatch):
    clock = Clock()
    stop = StopIn(monkeypatch, "stage 0/1", 100, sigint if kind == "signal" else clock.end)
    with catching():
        r = solve(flock, maxiter=100, quiet=True, stop="method", deadline=clock,
                  homotopy=[shifted(flock, np.array([3.0, -3.0]))])
    assert stop.sent and stop.after == 0
    level, own = r.stages[:2]
    assert level["status"] == (INTERRUPTED if kind == "signal" else LIMIT)
    assert own["skipped"] == kind and own["nit"] == 0 and "not run" in own["message"]


@pytest.mark.parametrize("kind", ["signal", "time"])
def test_the_finish_stops_inside_a_step(kind, monkeypatch):
    clock = Clock()
    stop = StopIn(monkeypatch, "finish (", 5, sigint if kind == "signal" else clock.end)
    prob = tight(swing())
    with catching():
        r = solve(prob, maxiter=50, quiet=True, finish="effort", stop="method",
                  deadline=clock)
    assert stop.sent and stop.after == 0
    assert r.status in ((INTERRUPTED,) if kind == "signal" else (LIMIT, 0)), r.message
    said = "was interrupted" if kind == "signal" else "ran out of time"
    assert f"the finish {said}" in r.message and "kept" in r.stages[-1]["message"]


@pytest.mark.parametrize("kind", ["signal", "time"])
def test_multiple_shooting_rounds_stop_at_their_next_step(kind, monkeypatch):
    clock = Clock()
    stop = StopIn(monkeypatch, "multiple shooting", 2, sigint if kind == "signal" else clock.end,
                  iterations=True)
    with catching():
        r = solve(sheet_problem(ground=False), maxiter=20, quiet=True, stop="method",
                  deadline=clock, shooting={"segments": 3, "rounds": 2})
    assert stop.sent and stop.after == 0
    assert r.stages[0]["status"] == (INTERRUPTED if kind == "signal" else LIMIT)
    assert r.stages[0]["nit"] == 2 and np.isfinite(r.fun)


@pytest.mark.parametrize("kind", ["signal", "time"])
def test_shooting_workers_are_stopped_while_the_run_waits_for_them(kind, monkeypatch):
    """The stop comes while the run waits for its two workers' sweep (sent a moment after
    the first iteration): the pool checks while it waits, ends its workers and the stage
    stops with its best point."""
    clock = Clock()
    later = sigint if kind == "signal" else clock.end
    StopIn(monkeypatch, "multiple shooting", 1,
           lambda: threading.Timer(0.05, later).start(), iterations=True)
    with catching():
        r = solve(sheet_problem(ground=False), maxiter=40, quiet=True, stop="method",
                  deadline=clock, shooting={"segments": 3, "rounds": 1, "workers": 2})
    assert r.stages[0]["status"] == (INTERRUPTED if kind == "signal" else LIMIT)
    assert r.stages[0]["nit"] >= 1 and np.isfinite(r.fun)
    assert multiprocessing.active_children() == []  # no worker left behind


@pytest.mark.parametrize("kind", ["signal", "time"])
def test_a_long_simulation_stops_at_its_next_step(flock, kind, monkeypatch):
    clock = Clock()
    long = load_problem("flock_path", agents=6, steps=2000)
    stop = StopIn(monkeypatch, "simulating", 100, sigint if kind == "signal" else clock.end)
    with catching(), limited(clock), pytest.raises(Interrupted if kind == "signal"
                                                   else OutOfTime):
        long.simulate(long.initial_controls())
    assert stop.sent and stop.after == 0


@pytest.mark.parametrize("kind", ["signal", "time"])
def test_the_start_of_a_run_stops_and_writes_nothing(kind, monkeypatch, tmp_path, capsys):
    """The command's first simulation (the start's) is a stage too: a signal ends the run
    (exit 130), its time limit too (exit 3), nothing written either way."""
    import casadi_keyframe.runs.solve as run

    clock = Clock()
    if kind == "time":
        monkeypatch.setattr(run, "Deadline", lambda started, limit: clock)
    stop = StopIn(monkeypatch, "the start", 100, sigint if kind == "signal" else clock.end)
    code = main(["solve", "flock_path", "--set", "agents=6", "--set", "steps=400", "--quiet",
                 "--no-animation", "--no-viewer", "--out", str(tmp_path / "run")])
    assert stop.sent and stop.after == 0
    assert code == (130 if kind == "signal" else 3)
    assert sorted(p.name for p in (tmp_path / "run").iterdir()) == []
    said = capsys.readouterr().out
    assert "nothing" in said


def test_drawing_stops_at_its_next_frame(flock, monkeypatch, tmp_path):
    from casadi_keyframe import render

    stop = StopIn(monkeypatch, "drawing", 4, sigint)
    traj = flock.simulate(flock.initial_controls())
    with catching(), pytest.raises(Interrupted):
        render.animate(flock, traj, tmp_path / "a.gif")
    assert stop.sent and stop.after == 0
    assert not list(tmp_path.iterdir())  # no half-drawn picture


def test_drawing_is_held_to_its_own_time(flock, monkeypatch, tmp_path):
    """Each frame takes "1 s" on a clock of the test's: with 10 s to draw, the frames past
    what fits are thinned, every keyframe and the last kept, and the animation says so."""
    import casadi_keyframe.render.frames as frames

    ticks = iter(range(10 ** 6))
    monkeypatch.setattr(frames.time, "monotonic", lambda: float(next(ticks)))
    long = load_problem("flock_path", agents=4, steps=60)
    drawn = []
    real = frames.write_gif
    monkeypatch.setattr(frames, "write_gif",
                        lambda *a, **k: drawn.append(real(*a, **k)) or drawn[-1])
    import casadi_keyframe.render.flock as flock_render
    monkeypatch.setattr(flock_render, "write_gif", frames.write_gif)
    with progress.reporting(quiet=True) as shown:
        lines = []
        monkeypatch.setattr(shown, "line", lambda text, stage=False: lines.append(text))
        flock_render.animate(long, long.simulate(long.initial_controls()), tmp_path / "a.gif",
                             limit=10.0)
    assert 0 < drawn[0] <= 10 < 61  # 61 frames planned, the clock allows about 8
    assert any("frames drawn, to fit its 10 s" in line for line in lines)
    assert (tmp_path / "a.gif").stat().st_size > 0


def test_a_reporter_never_goes_silent_and_quiet_keeps_the_stage_lines():
    """Away from a terminal a line comes once ``every`` seconds pass without one (its
    thread says it while the work is inside one long step); quiet keeps stage lines and
    notes only."""
    import io
    import time

    from casadi_keyframe.progress import Reporter, _reporters, advance, note, say, task

    stream = io.StringIO()
    reporter = Reporter(stream, every=0.05).start()
    _reporters.append(reporter)
    try:
        with task("solving", 10, "iterations"):
            advance(facts="objective 1")
            time.sleep(0.3)  # one long step: the thread speaks
            say("stage 0: done", stage=True)
    finally:
        _reporters.remove(reporter)
        reporter.stop()
    lines = stream.getvalue().splitlines()
    assert any(line.startswith("solving 1/10 iterations, objective 1;") and "left" in line
               for line in lines)
    assert "stage 0: done" in lines
    quiet = io.StringIO()
    reporter = Reporter(quiet, quiet=True, every=0.05).start()
    _reporters.append(reporter)
    try:
        with task("solving", 10):
            time.sleep(0.2)
            say("a line for the terminal only")
            say("stage 0: done", stage=True)
            note("quads split")
    finally:
        _reporters.remove(reporter)
        reporter.stop()
    assert quiet.getvalue().splitlines() == ["stage 0: done", "note: quads split"]
