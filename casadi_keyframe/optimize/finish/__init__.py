"""The finish: a solve's last stage, with the keyframes held as a constraint.

* :mod:`.stage`: :class:`Finish`, its options, and :func:`run_finish`, the stage;
* :mod:`.searches`: :func:`land` and :func:`lower_effort`, the searches it runs;
* :mod:`.constraint`: :class:`KeyframeConstraint`, the keyframes as residual rows over a
  window of late steps, and the control cost's Hessian there.
"""
from .constraint import KeyframeConstraint, control_hessian
from .searches import land, lower_effort
from .stage import Finish, check_finish, finish_options, run_finish

__all__ = ["Finish", "KeyframeConstraint", "check_finish", "control_hessian",
           "finish_options", "land", "lower_effort", "run_finish"]
