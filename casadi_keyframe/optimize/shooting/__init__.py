"""Multiple shooting: the horizon in segments whose start states are unknowns too, and
their continuity held by multipliers or by IPOPT's constraints, on the optimizer's own
:class:`~casadi_keyframe.optimize.evaluator.Evaluator`.

* :mod:`.options`: :class:`ShootingOptions`, :func:`shooting_options`;
* :mod:`.form`: :class:`Shooting`, the variables, the merit and its exact gradient, the
  defects and their Jacobian;
* :mod:`.merit`: the merit as the evaluator evaluates it and an iteration's record reads it;
* :mod:`.segments`: a segment's sweeps through the public loops; :mod:`.workers` (this
  process, forked processes) and :mod:`.dask_pool` (Dask actors) run them;
* :mod:`.nodes`: where the node states start;
* :mod:`.stage`: :func:`run_shooting`, the stage (augmented-Lagrangian rounds) and
  :mod:`.ipopt_form`, the defects as IPOPT's constraints.
"""
from .form import Shooting
from .options import ShootingOptions, shooting_options
from .stage import run_shooting

__all__ = ["Shooting", "ShootingOptions", "run_shooting", "shooting_options"]
