"""What a search returns: :class:`Result`, in scipy's ``OptimizeResult`` vocabulary."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..state import Trajectory
from .outcome import STATUS


@dataclass
class Result:
    """Outcome of :func:`solve` (``x`` are the controls, the best point the search saw).

    ``status`` says how the search ended: 0 converged; 1 a limit (iterations, evaluations,
    ``time_limit``) was reached first; 2 the search failed (a line search found no lower
    point, an IPOPT error); 3 interrupted (Ctrl-C, SIGTERM).  ``success`` is ``status ==
    0`` and ``message`` says in a sentence what happened and, on failure, what to try.
    """

    x: np.ndarray
    fun: float
    jac: np.ndarray
    nit: int
    nfev: int
    success: bool
    status: int
    message: str
    method: str
    gradient: str
    trajectory: Trajectory | None = None
    history: list = field(default_factory=list)
    timings: dict = field(default_factory=dict)
    breakdown: dict = field(default_factory=dict)
    stages: list = field(default_factory=list)

    @property
    def start(self) -> dict:
        """Objective and keyframe error at the starting controls (of the first stage)."""
        first = self.stages[0] if self.stages else {}
        return {"objective": first.get("start_objective"),
                "keyframe_error": first.get("start_keyframe_error")}

    def summary(self) -> dict:
        """JSON-ready summary (no arrays); ``stages`` has one entry per continuation stage
        (time step, iterations, evaluations, best objective at that step, status, seconds)."""
        return {"fun": self.fun, "nit": self.nit, "nfev": self.nfev, "success": self.success,
                "status": self.status, "status_name": STATUS[self.status],
                "message": self.message, "method": self.method, "gradient": self.gradient,
                "timings": self.timings, "breakdown": self.breakdown, "stages": self.stages,
                "gradient_norm": float(np.linalg.norm(self.jac))}
