"""Who sweeps the segments of a multiple-shooting evaluation: this process
(:class:`Serial`), local worker processes (:class:`LocalPool`, the default with more than
one worker) or the workers of a Dask cluster (:class:`~.dask_pool.DaskPool`).

A runner's ``forward(items)`` runs the segments ``items`` names (segment -> ``(start,
external, carried)``, ``carried`` what the step before its first one carried) and returns
segment -> ``(x, v, used, carry)``: its frames, the carry it started from and the one its
last step leaves; it keeps the records where it ran.  ``backward(cotangents)`` pulls the
cotangents back through those records and returns each segment's ``(d/d external, d/d
start)``.  A worker owns fixed
segments, so a segment's backward sweep runs where its forward sweep kept its
factorisations.  A failed simulation in any segment raises
:class:`~casadi_keyframe.state.SimulationError` here, naming the segment.
"""
from __future__ import annotations

import multiprocessing
import os
import signal
import traceback

from ...interrupts import check
from ...state import SimulationError
from .segments import AskedSweeps, SegmentRunner

WAIT = 0.1  # s: how often a pool waiting for its workers checks for a signal and the time


class Serial:
    """Every segment in this process, one after the other."""

    workers = 1

    def __init__(self, problem, spans):
        self.runner = SegmentRunner(problem.model, problem.integrator, problem.dt,
                                    dict(enumerate(spans)))

    def forward(self, items: dict) -> dict:
        """The segments in order, each after the previous one run here starting from what
        that one carried (so they join as one run does)."""
        out = {}
        for k in sorted(items):
            start, external, carried = items[k]
            if k - 1 in out:
                carried = out[k - 1][3]
            x, v, carry = _named(k, self.runner.forward, k, start, external, carried)
            out[k] = (x, v, carried, carry)
        return out

    def backward(self, cotangents) -> list:
        return [_named(k, self.runner.backward, k, gx, gv)
                for k, (gx, gv) in enumerate(cotangents)]

    def rows(self, ends: dict) -> dict:
        """Segment -> its end-state Jacobian rows (:meth:`SegmentRunner.rows`), for the
        segments ``ends`` names (segment -> list of end cotangents)."""
        return {k: _named(k, self.runner.rows, k, e) for k, e in ends.items()}

    def close(self) -> None:
        self.runner.close()


def _named(k, call, *args):
    """``call(*args)``, a SimulationError naming segment ``k``."""
    try:
        return call(*args)
    except SimulationError as err:
        raise SimulationError(f"segment {k}: {err}", err.step) from None


class LocalPool(AskedSweeps):
    """``workers`` forked processes, each owning the segments ``k`` with ``k % workers``
    equal to its number; they inherit the problem (no rebuild), ignore Ctrl-C (this
    process stops them) and end with :meth:`close`.  Needs the ``fork`` start method
    (Linux, macOS); ValueError otherwise."""

    def __init__(self, problem, spans, workers: int):
        if "fork" not in multiprocessing.get_all_start_methods():
            raise ValueError("local shooting workers need the 'fork' start method, which "
                             "this platform lacks: use workers=1 or a Dask scheduler")
        self.workers = min(int(workers), len(spans))
        context = multiprocessing.get_context("fork")
        self.owned = [[k for k in range(len(spans)) if k % self.workers == w]
                      for w in range(self.workers)]
        self.pipes, self.processes = [], []
        for w in range(self.workers):
            mine, theirs = context.Pipe()
            spans_w = {k: spans[k] for k in self.owned[w]}
            proc = context.Process(target=_serve, args=(theirs, problem, spans_w), daemon=True)
            proc.start()
            theirs.close()
            self.pipes.append(mine)
            self.processes.append(proc)

    def _ask(self, command, per_segment) -> list:
        """``command`` for each segment of ``per_segment`` (a list over all segments, or a
        dict of some): their answers, a list or a dict alike."""
        some = isinstance(per_segment, dict)
        items = per_segment if some else dict(enumerate(per_segment))
        asked = []
        for w, pipe in enumerate(self.pipes):
            mine = [(k, items[k]) for k in self.owned[w] if k in items]
            if mine:
                pipe.send((command, mine))
                asked.append(pipe)
        out, failure = {}, None
        for pipe in asked:
            self._wait(pipe)
            kind, payload = pipe.recv()
            if kind == "ok":
                out.update(payload)
            elif failure is None:
                failure = (kind, payload)
        if failure is not None:
            kind, payload = failure
            if kind == "simulation":
                raise SimulationError(*payload)
            raise RuntimeError(f"a shooting worker failed:\n{payload}")
        return out if some else [out[k] for k in range(len(per_segment))]

    def rows(self, ends: dict) -> dict:
        per_segment = [ends.get(k, []) for k in range(sum(map(len, self.owned)))]
        return dict(enumerate(self._ask("rows", per_segment)))

    def _wait(self, pipe) -> None:
        """Wait for a worker's answer, checking for a signal and the time limit; on either
        the workers, busy with a sweep no one will read, are stopped at once."""
        while not pipe.poll(WAIT):
            try:
                check()
            except BaseException:
                self.stop()
                raise

    def stop(self) -> None:
        """End every worker now (their answers are not needed)."""
        for proc in self.processes:
            if proc.is_alive():
                proc.terminate()
        for proc in self.processes:
            proc.join(timeout=5)
        for pipe in self.pipes:
            pipe.close()
        self.pipes, self.processes = [], []

    def close(self) -> None:
        for pipe in self.pipes:
            try:
                pipe.send(("close", []))
            except (BrokenPipeError, OSError):
                pass
        for proc in self.processes:
            proc.join(timeout=5)
            if proc.is_alive():
                proc.terminate()
                proc.join()
        self.pipes, self.processes = [], []


def _serve(pipe, problem, spans) -> None:
    """A worker's loop: run the commands sent over ``pipe`` on its segments."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    runner = SegmentRunner(problem.model, problem.integrator, problem.dt, spans)
    while True:
        try:
            command, items = pipe.recv()
        except EOFError:
            break
        if command == "close":
            break
        try:
            if command == "forward":
                out = {k: runner.forward(k, s, e, c) for k, (s, e, c) in items}
            elif command == "rows":
                out = {k: runner.rows(k, ends) if ends else [] for k, ends in items}
            else:
                out = {k: runner.backward(k, gx, gv) for k, (gx, gv) in items}
            pipe.send(("ok", out))
        except SimulationError as err:
            k = next((k for k, _ in items if k not in runner.kept), items[0][0])
            pipe.send(("simulation", (f"segment {k}: {err}", err.step)))
        except Exception:  # noqa: BLE001 (reported to the parent, which raises it)
            pipe.send(("crash", f"worker {os.getpid()}: {traceback.format_exc()}"))
    runner.close()
    pipe.close()


def segment_runner(problem, spans, workers: int = 1, scheduler: str | None = None,
                   origin=None):
    """The runner for ``workers`` (1: this process) or a Dask ``scheduler`` address (whose
    workers rebuild ``problem`` from its file, or ``origin``'s at its time step)."""
    if scheduler is not None:
        from .dask_pool import DaskPool
        return DaskPool(problem, spans, scheduler, workers, origin)
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        raise ValueError(f"workers must be a whole number >= 1 (1: this process), got "
                         f"{workers!r}")
    return Serial(problem, spans) if workers == 1 or len(spans) == 1 else LocalPool(
        problem, spans, workers)
