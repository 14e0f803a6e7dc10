"""What a local sweep worker runs as it starts (a Dask preload): it ignores SIGINT and gives
tqdm a thread lock.

A Ctrl-C at the terminal reaches the whole process group.  The workers the cluster starts
first inherit an ignored SIGINT from the sweep's process; one Dask starts again after a
worker died does not, and without this a Ctrl-C would stop it mid-point with a traceback
instead of letting the sweep's own process stop the cluster.

tqdm locks its bars with a multiprocessing RLock, which under the spawn start method Dask's
workers run with is a named semaphore; a worker stopped before it exits cleanly (killed, or
closed mid-point after a Ctrl-C) leaves it behind, and the resource tracker then prints
"There appear to be 1 leaked semaphore objects" as the sweep ends.  A point's bars are off
and never shared between processes, so a thread lock serves.
"""
import signal
import threading


def dask_setup(worker) -> None:  # noqa: ARG001 - Dask's preload entry point
    """Ignore SIGINT in this worker process (from its main thread, where it can be set) and
    lock tqdm's bars with a thread lock."""
    from tqdm.std import tqdm

    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGINT, signal.SIG_IGN)
    tqdm.set_lock(threading.RLock())
