"""Workers that die during a sweep, named with the points they were solving: Dask starts
those points again on another worker by itself, silently; the terminal should say so.

The scheduler counts, per task, the workers that died while running it (its
``suspicious`` count, which Dask compares with ``allowed-failures``); a count that grew since
the last poll is a start lost.  A scheduler that cannot run this library's code (a remote
cluster without it) is watched from outside instead: a worker address that vanished
between two polls took the points it was running at the previous poll.
"""
from __future__ import annotations

from collections import Counter


def lost_starts(keys, dask_scheduler=None) -> dict:
    """On the scheduler: how many workers died while running each of ``keys``."""
    tasks = dask_scheduler.tasks
    return {key: tasks[key].suspicious for key in keys if key in tasks}


class WorkerWatch:
    """At each :meth:`poll`, ``say`` a line for each point that lost a start to a dying
    worker since the previous poll; ``tries`` is how many starts a point gets (None when
    the cluster's own setting decides: a cluster given by its scheduler's address)."""

    def __init__(self, say, tries: int | None = None):
        self.say, self.tries = say, tries
        self.lost: Counter = Counter()
        self.inside = True  # whether the scheduler runs lost_starts
        self.workers: set | None = None
        self.running: dict = {}

    def poll(self, client, labels: dict) -> None:
        """Look at the cluster now; ``labels`` maps the keys of the points submitted to
        their names."""
        counts = self._counts(client, labels)
        for key, count in counts.items():
            if count > self.lost[key]:
                self.lost[key] = count
                self.say(f"sweep: a worker died while solving {labels[key]}: "
                         + self.next_start(count))

    def _counts(self, client, labels: dict) -> dict:
        """Lost starts per key, asked of the scheduler, or seen from outside."""
        if self.inside:
            try:
                return client.run_on_scheduler(lost_starts, list(labels))
            except Exception:  # noqa: BLE001 - a scheduler without this library
                self.inside = False
        try:
            workers = set(client.nthreads())
            running = {w: [k for k in keys if k in labels]
                       for w, keys in client.processing().items()}
        except Exception:  # noqa: BLE001 - the scheduler busy or gone: look next time
            return {}
        counts = Counter(self.lost)
        for worker in (self.workers or set()) - workers:
            counts.update(self.running.get(worker, ()))
        self.workers, self.running = workers, running
        return {k: n for k, n in counts.items() if k in labels}

    def next_start(self, lost: int) -> str:
        """What happens to a point that has lost ``lost`` starts."""
        if self.tries is None:
            return "Dask starts it again on another worker (up to the cluster's allowed-failures)"
        if lost >= self.tries:
            return (f"that was its last of {self.tries} starts (--tries): it is reported "
                    "failed")
        return f"Dask starts it again on another worker (start {lost + 1} of {self.tries})"
