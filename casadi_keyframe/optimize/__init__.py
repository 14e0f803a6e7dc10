"""The optimizer layer: :func:`solve` and what it is built from.

* :mod:`.search`: :func:`solve`, one optimisation through its stages;
* :mod:`.result`: the :class:`Result` every search returns;
* :mod:`.evaluator`: the memoised objective every method sees (multiple shooting's merit
  too);
* :mod:`.methods`: :data:`METHODS`, the table of search methods and their options;
  :mod:`.lbfgsb`, :mod:`.ipopt`: the methods, one file each;
* :mod:`.stages`: the problems a solve goes through, coarse to fine, and :mod:`.transfer`:
  controls carried from one mesh of a cloth to another;
* :mod:`.metrics`: the smooth metrics a search can run in;
* :mod:`.outcome`: status codes and the methods' messages translated;
* :mod:`.augmented_lagrangian`: :func:`solve_augmented`, hard keyframes in rounds;
* :mod:`.shooting`: multiple shooting, a stage of :func:`solve` (``shooting=K``);
* :mod:`.constrained`: :func:`lower_effort`, less control effort with the keyframes held.
"""
from .augmented_lagrangian import solve_augmented
from .finish import lower_effort
from .methods import METHODS, Method
from .outcome import CONVERGED, FAILED, INTERRUPTED, LIMIT, STATUS
from .result import Result
from .search import solve
from .stages import stage_problems

__all__ = ["CONVERGED", "FAILED", "INTERRUPTED", "LIMIT", "METHODS", "STATUS", "Method",
           "Result", "lower_effort", "solve", "solve_augmented", "stage_problems"]
