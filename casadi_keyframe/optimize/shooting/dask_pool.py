"""Multiple shooting's segments on the workers of a running Dask cluster (the one ``sweep``
uses, ``--scheduler``): one actor per worker owns fixed segments, rebuilds the problem
from its file and overrides (a worker shares no memory with this process), and keeps each
forward pass's records for its backward pass, as a local worker does
(:class:`~.workers.LocalPool`)."""
from __future__ import annotations

from ...interrupts import check
from .segments import AskedSweeps, SegmentRunner

WAIT = 0.2  # s: how often the pool waiting for an actor checks for a signal and the time


def _answer(future, pool):
    """An actor's answer, a signal or the time limit checked while it comes (the pool
    stopped on either)."""
    while True:
        try:
            return future.result(timeout=WAIT)
        except TimeoutError:
            pass
        try:
            check()
        except BaseException:
            pool.stop()
            raise


def recipe(problem, origin):
    """How a worker rebuilds ``problem``: ``(problem file, overrides, dt or None)`` from its
    own source, or from ``origin``'s (the solve's problem) at another time step; ValueError
    when neither says (a problem not built from a file)."""
    for p, dt in ((problem, None), (origin, problem.dt)):
        source = getattr(p, "source", None)
        if source is not None and (p is problem or p.model is problem.model):
            return str(source.module.__file__), dict(source.overrides), dt
    raise ValueError(f"{problem.name}: segments on a Dask cluster rebuild the problem from "
                     "its file, and this one was not built from a problem file (or was "
                     "changed since); solve it with local shooting workers instead")


class SegmentActor:
    """A Dask actor: some segments of the problem a recipe rebuilds."""

    def __init__(self, recipe_, spans: dict):
        from ...loading import build_problem, load_module

        path, overrides, dt = recipe_
        problem = build_problem(load_module(path), **overrides)
        if dt is not None:
            problem = problem.resampled(dt)
        self.runner = SegmentRunner(problem.model, problem.integrator, problem.dt, spans)

    def run(self, command: str, items: list):
        from ...state import SimulationError

        try:
            if command == "forward":
                return "ok", {k: self.runner.forward(k, s, e, c) for k, (s, e, c) in items}
            if command == "rows":
                return "ok", {k: self.runner.rows(k, e) if e else [] for k, e in items}
            return "ok", {k: self.runner.backward(k, gx, gv) for k, (gx, gv) in items}
        except SimulationError as err:
            return "simulation", (str(err), err.step)

    def close(self) -> None:
        self.runner.close()


class DaskPool(AskedSweeps):
    """The segments spread over the cluster's workers (at most ``workers`` of them, one
    actor each), asked in parallel like :class:`~.workers.LocalPool`."""

    def __init__(self, problem, spans, scheduler: str, workers: int = 1, origin=None):
        try:
            import distributed
        except ImportError:
            raise ValueError("segments on a Dask cluster need Dask distributed: pip install "
                             "'casadi_keyframe[sweep]'") from None
        made = recipe(problem, origin or problem)
        self.client = distributed.Client(scheduler, timeout=10)
        addresses = sorted(self.client.scheduler_info()["workers"])
        if not addresses:
            self.client.close()
            raise ValueError(f"--scheduler {scheduler}: the scheduler has no workers")
        count = min(max(workers, len(addresses)), len(spans), len(addresses))
        self.owned = [[k for k in range(len(spans)) if k % count == w] for w in range(count)]
        self.actors = [self.client.submit(SegmentActor, made, {k: spans[k] for k in mine},
                                          actor=True, workers=[addr]).result()
                       for mine, addr in zip(self.owned, addresses)]
        self.count = len(spans)

    def _ask(self, command, per_segment) -> list:
        """``command`` for each segment of ``per_segment`` (a list over all segments, or a
        dict of some): their answers, a list or a dict alike."""
        from ...state import SimulationError

        some = isinstance(per_segment, dict)
        items = per_segment if some else dict(enumerate(per_segment))
        futures = [actor.run(command, [(k, items[k]) for k in mine if k in items])
                   for actor, mine in zip(self.actors, self.owned)
                   if any(k in items for k in mine)]
        out = {}
        for future in futures:
            kind, payload = _answer(future, self)
            if kind != "ok":
                raise SimulationError(*payload)
            out.update(payload)
        return out if some else [out[k] for k in range(self.count)]

    def rows(self, ends: dict) -> dict:
        return dict(enumerate(self._ask("rows", [ends.get(k, []) for k in range(self.count)])))

    def stop(self) -> None:
        """Leave the actors' sweeps unread: the client goes, the cluster stays."""
        self.actors = []
        self.client.close()

    def close(self) -> None:
        for actor in getattr(self, "actors", []):
            try:
                actor.close().result()
            except Exception:  # noqa: BLE001 (a worker gone: nothing left to give back)
                pass
        self.actors = []
        self.client.close()
