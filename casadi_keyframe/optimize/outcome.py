"""How a search ended: a status code and a sentence with the likely cause and fix.

scipy's L-BFGS-B and IPOPT end with terse codes ("ABNORMAL: ", "Restoration_Failed");
:func:`lbfgsb_outcome` and :func:`ipopt_outcome` translate them into one of four
documented statuses (scipy's ``OptimizeResult.status`` style) and a message that says what
happened and what to try, the solver's own words kept in brackets.
"""
from __future__ import annotations

CONVERGED, LIMIT, FAILED, INTERRUPTED = 0, 1, 2, 3
STATUS = {CONVERGED: "converged", LIMIT: "limit reached", FAILED: "search failed",
          INTERRUPTED: "interrupted"}

INACCURATE = ("the gradient may be inaccurate or the problem badly scaled: compare the "
              "gradient routes (gradcheck), use an exact route, or bring the keyframe and "
              "control weights closer")

_IPOPT_FAILURES = {
    "Search_Direction_Becomes_Too_Small": "the search direction became too small to make "
    "progress; " + INACCURATE,
    "Restoration_Failed": "IPOPT's restoration phase failed after a step it could not "
    "accept; " + INACCURATE,
    "Error_In_Step_Computation": "IPOPT could not compute a step (the limited-memory Hessian "
    "broke down); " + INACCURATE,
    "Invalid_Number_Detected": "the objective or its gradient returned NaN or inf",
    "NonIpopt_Exception_Thrown": "an error was raised inside an objective or gradient "
    "evaluation (CasADi printed it above)",
    "Diverging_Iterates": "the controls grew without bound: the objective may be unbounded "
    "below; bound the controls or raise the smoothness weight",
    "Infeasible_Problem_Detected": "the control bounds admit no point: check lower <= upper",
    "Not_Enough_Degrees_Of_Freedom": "the problem has no free controls",
}


def lbfgsb_outcome(message: str, *, maxiter: int, maxfun: int) -> tuple[int, str]:
    """``(status, sentence)`` for scipy's L-BFGS-B ``message`` (old and new spellings)."""
    raw = " ".join(str(message).replace("_", " ").split()).rstrip(": ")
    text, tag = raw.upper(), f" [L-BFGS-B: {raw}]"
    if text.startswith("CONVERGENCE"):
        why = ("the projected gradient is below gtol" if "GRADIENT" in text else
               "the objective stopped decreasing (relative reduction below ftol)")
        return CONVERGED, f"converged: {why}{tag}"
    if "ITERATIONS" in text:
        return LIMIT, (f"iteration limit reached ({maxiter} iterations in this stage) before "
                       f"converging{tag}")
    if "EVALUATIONS" in text or "F,G" in text:
        return LIMIT, (f"evaluation limit reached ({maxfun} evaluations in this stage) before "
                       f"converging{tag}")
    if text.startswith("ABNORMAL"):
        return FAILED, ("line search failed: no step along the search direction lowered the "
                        f"objective; {INACCURATE}{tag}")
    if "ROUNDING" in text:
        return FAILED, ("rounding errors prevent progress: the objective is flat or noisy at "
                        f"double precision here; {INACCURATE}{tag}")
    return FAILED, f"L-BFGS-B stopped without converging{tag}"


def ipopt_outcome(return_status: str, *, maxiter: int) -> tuple[int, str]:
    """``(status, sentence)`` for IPOPT's ``return_status`` (an interrupt is handled by the
    caller, which knows it happened)."""
    tag = f" [IPOPT: {return_status}]"
    if return_status in ("Solve_Succeeded", "Feasible_Point_Found"):
        return CONVERGED, f"converged{tag}"
    if return_status == "Solved_To_Acceptable_Level":
        return CONVERGED, f"converged to IPOPT's acceptable tolerance{tag}"
    if return_status == "Maximum_Iterations_Exceeded":
        return LIMIT, (f"iteration limit reached ({maxiter} iterations in this stage) before "
                       f"converging{tag}")
    if return_status in ("Maximum_WallTime_Exceeded", "Maximum_CpuTime_Exceeded"):
        return LIMIT, f"time limit reached before converging{tag}"
    why = _IPOPT_FAILURES.get(return_status, "IPOPT failed")
    return FAILED, f"search failed: {why}{tag}"


HARD = ("hold the keyframes hard (rounds), raise their weights, or start closer (a guess, "
        "multiple shooting)")


def judge(status: int, message: str, verdict) -> tuple[int, str]:
    """How a search really ended, given how its method stopped (``status``, ``message``)
    and the goal's :class:`~.goal.Verdict` at its best point: "converged" only with every
    keyframe within its tolerance; a method that stopped short of the goal failed, and the
    message names each keyframe still missed.  Without a goal (no tolerance declared), and
    for an interrupt, the method's word stands."""
    if status == INTERRUPTED or not verdict.checked:
        return status, message
    if verdict.met:
        if status == FAILED:  # the goal is met: how the method then stopped is a detail
            return CONVERGED, (f"converged: {verdict.describe()} (then the method stopped: "
                               f"{message.split('; ')[0]})")
        return status, f"{message}; {verdict.describe()}"
    missed = verdict.describe()
    if status == CONVERGED:
        return FAILED, (f"search failed: the method stopped short of the goal ({message}); "
                        f"{missed}; {HARD}")
    return status, f"{message}; {missed}"
