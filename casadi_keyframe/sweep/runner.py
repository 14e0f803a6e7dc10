"""Run a sweep's points on Dask distributed: a local cluster of worker processes by default,
or any running cluster given by its scheduler's address (the library never starts remote
machines: ``dask scheduler`` / ``dask worker``, ``dask-jobqueue`` or a Kubernetes operator do).

Each point is one task, run by :func:`.tasks.run_task` on a worker with one thread (CasADi
and the optimizers hold the GIL: more threads per process would only queue).  Dask's own
fault handling is used as it is: a worker that dies (killed, out of memory) loses only the
points it was running, which the scheduler gives to another worker, up to its
``allowed-failures`` (``tries - 1`` for the local cluster); a point past that is reported
failed with the reason.  SIGINT and SIGTERM stop the sweep at the next poll
(:mod:`..interrupts`): waiting points are cancelled, the finished ones are on disk.
"""
from __future__ import annotations

import contextlib
import gc
import logging
import os
import signal
import threading
from pathlib import Path

from ..interrupts import Interrupted, catching, check, deferred
from ..saved import write_json
from . import worker_setup
from .progress import Progress
from .tasks import ERROR, ROW, run_task
from .watch import WorkerWatch

POLL_SECONDS = 0.5
INSTALL_HINT = ("the sweep runs on Dask distributed, which is not installed: "
                "pip install 'casadi_keyframe[sweep]'")


def _distributed():
    try:
        import distributed
    except ImportError:
        raise ValueError(INSTALL_HINT) from None
    return distributed


@contextlib.contextmanager
def connect(*, workers: int | None = None, scheduler: str | None = None, tries: int = 3,
            timeout: float = 10.0):
    """A Dask client: of the running cluster at ``scheduler``, or of a new local cluster of
    ``workers`` processes (default one per core), one thread each, listening on loopback
    only, where a point may be started ``tries`` times before it is reported failed.  The
    local workers ignore SIGINT, so Ctrl-C stops only this process, which stops them; the
    cluster is closed whole even if a second Ctrl-C comes (inside
    :func:`~casadi_keyframe.interrupts.catching`)."""
    distributed = _distributed()
    if tries < 1:
        raise ValueError(f"--tries must be at least 1, got {tries}")
    if scheduler:
        if workers is not None:
            raise ValueError("--workers sets the size of a local cluster: with --scheduler "
                             "the running cluster's own workers solve the points; give one")
        with _client_of(distributed, scheduler, timeout) as client:
            yield client
        return
    import dask

    cluster = client = None
    try:
        # the worker processes started now inherit the ignored SIGINT; those Dask starts
        # again after a death ignore it from their preload on (.worker_setup)
        with _ignoring_sigint(), dask.config.set(
                {"distributed.scheduler.allowed-failures": tries - 1}):
            cluster = distributed.LocalCluster(
                n_workers=workers or os.cpu_count() or 1, threads_per_worker=1,
                processes=True, host="127.0.0.1", dashboard_address=None,
                silence_logs=logging.ERROR, preload=[worker_setup.__name__])
        client = distributed.Client(cluster)
        yield client
    finally:
        with deferred():  # a second Ctrl-C would leave the cluster half closed
            if client is not None:
                client.close()
            if cluster is not None:
                cluster.close()


@contextlib.contextmanager
def _ignoring_sigint():
    """SIGINT ignored within the block (in the main thread; elsewhere it cannot be set)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)


@contextlib.contextmanager
def _client_of(distributed, address: str, timeout: float):
    """A client of the scheduler at ``address`` with at least one worker, or ValueError."""
    try:
        client = distributed.Client(address, timeout=timeout)
    except (OSError, ValueError, TypeError) as err:
        # the half-made client closes itself when collected: do it now, not inside the
        # start of the next client (seen: a deadlock in distributed's LoopRunner)
        err.__traceback__ = None
        gc.collect()
        raise ValueError(f"--scheduler {address}: cannot reach a Dask scheduler there "
                         f"({type(err).__name__}: {' '.join(str(err).split())[:200]}); give "
                         "the address 'dask scheduler' printed, e.g. tcp://10.0.0.5:8786, "
                         "or leave --scheduler out to start a local cluster") from None
    try:
        try:
            client.wait_for_workers(1, timeout=timeout)
        except (TimeoutError, OSError):
            raise ValueError(f"--scheduler {address}: the scheduler has no workers; start "
                             f"some with 'dask worker {address} --nthreads 1'") from None
        yield client
    finally:
        client.close()


def check_workers(client, paths) -> int:
    """The number of worker threads; ValueError if a worker cannot import this library or
    cannot see one of ``paths`` (the output folder, the problem file: a remote cluster needs
    a filesystem shared with this machine, at the same paths)."""
    try:
        unseen = client.run(_unseen, [str(p) for p in paths])
    except Exception as err:  # noqa: BLE001 - unpickling fails on a worker without the library
        raise ValueError(f"the workers cannot run casadi_keyframe ({type(err).__name__}: "
                         f"{err}); install the same version on every worker") from None
    blind = {w: missing for w, missing in unseen.items() if missing}
    if blind:
        worker, missing = sorted(blind.items())[0]
        raise ValueError(f"{len(blind)} worker(s), e.g. {worker}, cannot see {', '.join(missing)}:"
                         " on a remote cluster --out and the problem file must be on a "
                         "filesystem the workers share with this machine, at the same paths")
    return worker_threads(client)


def _unseen(paths: list) -> list:
    return [p for p in paths if not os.path.exists(p)]


def run_specs(client, specs: list[dict], *, progress: Progress, tries: int | None = None):
    """Run every point spec on the cluster; ``(rows, signum)``: the rows of the points that
    finished (failed ones included, with their reason) and the signal that stopped the
    sweep early, or None.  A worker that dies is named with the points it was running
    (:class:`.watch.WorkerWatch`; ``tries`` the starts a point gets, None if the cluster
    decides).

    Points are handed to the scheduler only as worker threads free up (not all at once: a
    small group of tasks is not queued by Dask but spread over the workers at once, so a
    dying worker would take its queued points' tries with it, and "running" would count
    points that only wait)."""
    distributed = _distributed()
    waiting, futures, rows, signum = list(specs), {}, [], None
    watch = WorkerWatch(progress.note, tries)
    with catching():
        try:
            while waiting or futures:
                check()
                watch.poll(client, {f.key: spec["label"] for f, spec in futures.items()})
                slots = worker_threads(client)
                while waiting and len(futures) < slots:
                    spec = waiting.pop(0)
                    futures[client.submit(run_task, spec, key=f"point-{spec['id']}",
                                          pure=False)] = spec
                try:
                    done = distributed.wait(list(futures), timeout=POLL_SECONDS,
                                            return_when="FIRST_COMPLETED").done
                except TimeoutError:
                    done = set()
                for future in done:
                    rows.append(_row_of(future, futures.pop(future)))
                    progress.point(rows[-1], running=len(futures), slots=slots)
                if not done:
                    progress.status(len(futures), slots)
        except (Interrupted, KeyboardInterrupt) as err:
            signum = getattr(err, "signum", signal.SIGINT)
            client.cancel(list(futures))
    return rows, signum


def worker_threads(client) -> int:
    """The worker threads the cluster has now (at least 1: points wait for a worker)."""
    try:
        return max(sum(client.nthreads().values()), 1)
    except Exception:  # noqa: BLE001 - the count only paces the submissions
        return 1


def _row_of(future, spec: dict) -> dict:
    """The row a finished task returned, or for a task Dask gave up on (its workers died,
    or the task could not run) a row with status ``error`` and the reason, written to the
    point's folder so the table and ``--resume`` see it."""
    if future.status == "finished":
        row = future.result()
    else:
        err = future.exception() if future.status == "error" else None
        name = type(err).__name__ if err is not None else future.status
        if name == "KilledWorker":
            reason = ("every worker that started it died (killed, out of memory or crashed); "
                      "see the workers' logs, give the workers more memory or raise --tries")
        else:
            reason = f"{name}: {' '.join(str(err).split())}" if err is not None else name
        row = {"point": spec["name"], **spec["values"], "start": spec.get("start", 0),
               "status": ERROR, "reason": reason, "seconds": 0.0,
               "path": spec["folder"], "spec_id": spec["id"]}
        Path(spec["folder"]).mkdir(parents=True, exist_ok=True)
        write_json(Path(spec["folder"]) / ROW, row)
    return {**row, "label": spec["label"]}
