"""Parameter sweeps, multi-start solves and study grids on Dask distributed.

    from casadi_keyframe.sweep import sweep
    result = sweep("flock_path", {"weight": [10, 100], "alpha": [1e-4, 1e-3]}, starts=2,
                   overrides={"agents": 20}, out="results/sweep", workers=2)
    result.rows, result.best, result.exit_code

Each point is solved as ``casadi-keyframe solve`` solves it, into its own folder; the table
(``sweep.csv``, ``sweep.parquet`` with pyarrow), ``sweep.png`` and ``sweep.json`` sum them
up.  :mod:`.grid` makes the points, :mod:`.tasks` runs one on a worker, :mod:`.runner`
drives the cluster, :mod:`.plan` plans and sums up a sweep, :mod:`.table` writes the table,
the accuracy studies' grids run on it from :mod:`casadi_keyframe.studies.sweeps`.
"""
from .plan import SWEEP_EXIT_CODES, SweepResult, report, sweep

__all__ = ["SWEEP_EXIT_CODES", "SweepResult", "report", "sweep"]
