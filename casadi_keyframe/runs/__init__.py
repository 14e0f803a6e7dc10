"""A solve run: a problem file solved into a results folder, with its exit code, what it
prints and the pictures and exports beside it; the command line and every point of a sweep
run solves this way (so it sits below both)."""
from .exits import EXIT_CODES, exit_code
from .outputs import draw, run_export, run_render
from .solve import SolveRun, resume_controls, run_solve, solve_run

__all__ = ["EXIT_CODES", "SolveRun", "draw", "exit_code", "resume_controls", "run_export",
           "run_render", "run_solve", "solve_run"]
