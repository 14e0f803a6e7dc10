"""What a local sweep worker runs as it starts (a Dask preload): it ignores SIGINT.

A Ctrl-C at the terminal reaches the whole process group.  The workers the cluster starts
first inherit an ignored SIGINT from the sweep's process; one Dask starts again after a
worker died does not, and without this a Ctrl-C would stop it mid-point with a traceback
instead of letting the sweep's own process stop the cluster.
"""
import signal
import threading


def dask_setup(worker) -> None:  # noqa: ARG001 - Dask's preload entry point
    """Ignore SIGINT in this worker process (from its main thread, where it can be set)."""
    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGINT, signal.SIG_IGN)
