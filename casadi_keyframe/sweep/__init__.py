"""Parameter sweeps, multi-start solves and study grids on Dask distributed.

    from casadi_keyframe.sweep import sweep
    result = sweep("flock_path", {"weight": [10, 100], "alpha": [1e-4, 1e-3]}, starts=2,
                   overrides={"agents": 20}, out="results/sweep", workers=2)
    result.rows, result.best, result.exit_code

Each point is solved as ``casadi-keyframe solve`` solves it, into its own folder; the table
(``sweep.csv``, ``sweep.parquet`` with pyarrow), ``sweep.png`` and ``sweep.json`` sum them
up.  :mod:`.grid` makes the points, :mod:`.tasks` runs one on a worker, :mod:`.runner`
drives the cluster, :mod:`.plan` plans and sums up a sweep, :mod:`.table` writes the table,
:mod:`.studies` runs the accuracy studies' grids.
"""
from .plan import SWEEP_EXIT_CODES, SweepResult, report, sweep
from .studies import STUDIES, study_sweep

__all__ = ["STUDIES", "SWEEP_EXIT_CODES", "SweepResult", "report", "study_sweep", "sweep"]
