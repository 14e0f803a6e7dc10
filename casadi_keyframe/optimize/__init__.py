"""The optimizer: :func:`solve` and what it is built from, in wings.

The request and the solve:

* :mod:`.settings`: :class:`SolveSettings`, one typed solve request (every default and
  every string form of a setting written once), and :mod:`.options`: the typed options its
  parts take (a method's own, multiple shooting's, the finish's, the rounds'), read once;
* :mod:`.search`: :func:`solve`, one optimisation through its stages, its rounds and its
  finish;
* :mod:`.stages`: the problems a solve goes through, coarse to fine, and :mod:`.transfer`:
  controls carried from one mesh of a cloth to another;
* :mod:`.rounds`: hard keyframes in rounds of an augmented Lagrangian, a stage of
  :func:`solve`, and :mod:`.multipliers`: the method of multipliers the rounds and multiple
  shooting share;
* :mod:`.metrics`: the smooth metrics a search can run in.

Bookkeeping:

* :mod:`.evaluator`: the one :class:`~.evaluator.Evaluator` every method sees;
* :mod:`.kept`: the one ranking of points, the best point kept and the Result made at it;
* :mod:`.deadline`: the one clock of a call;
* :mod:`.result`: the :class:`Result` every search returns, :mod:`.outcome`: status codes
  and the methods' messages translated, :mod:`.goal`: the animator's goal and its verdict,
  :mod:`.report`: one-line reports of a search.

Wings:

* :mod:`.methods`: :data:`METHODS`, one file per method, and the contract a method keeps;
* :mod:`.ipopt_callbacks`: the Callbacks that feed IPOPT numbers (the controls' and the
  positions' searches);
* :mod:`.residual`: the residual family, one linearization, descents and step-size rules;
* :mod:`.shooting`: multiple shooting, a stage of :func:`solve` (``shooting=K``);
* :mod:`.finish`: the last stage, with the keyframes held (:func:`lower_effort`,
  :func:`~.finish.land`);
* :mod:`.positions`: the problem in positions (the transcription), a method of
  :data:`METHODS` (``method="transcription"``).
"""
from .finish import lower_effort
from .methods import METHODS, Method
from .outcome import CONVERGED, FAILED, INTERRUPTED, LIMIT, STATUS
from .result import Result
from .search import solve, solve_augmented
from .settings import SolveSettings
from .stages import stage_problems

__all__ = ["CONVERGED", "FAILED", "INTERRUPTED", "LIMIT", "METHODS", "STATUS", "Method",
           "Result", "SolveSettings", "lower_effort", "solve", "solve_augmented",
           "stage_problems"]
