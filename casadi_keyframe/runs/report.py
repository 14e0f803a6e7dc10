"""What a solve run prints: its outcome, totals, stages and misses (:func:`report`), the
hint after it (:func:`hint`), what a second interrupt leaves on disk, and command lines a
user can type again (values as ``--set`` reads them)."""
from __future__ import annotations

from fractions import Fraction
from pathlib import Path

from ..adjoints import DEFAULT
from ..optimize.outcome import FAILED, LIMIT
from ..optimize.report import format_effort, format_misses, format_physical, format_stage
from ..optimize.settings import given_options
from ..saved import CHECKPOINT, RESULT

def format_value(value) -> str:
    """A default as typed on the command line: ``1/60`` rather than 0.016666666666666666."""
    if isinstance(value, float) and len(repr(value)) > 8:
        fraction = Fraction(value).limit_denominator(1000)
        if float(fraction) == value:
            return str(fraction)
    return str(value)


def set_value(value) -> str:
    """An override's value as ``--set`` reads it back: a sequence comma-separated."""
    if isinstance(value, (tuple, list)):
        return ",".join(format_value(v) for v in value)
    return format_value(value)


def report(result, summary, out) -> None:
    """Print the outcome: message, totals, each stage or round, the keyframe misses."""
    print(f"{summary['problem']}: {result.message}")
    print(f"  objective {summary['fun']:.6g}  iterations {result.nit}  evaluations "
          f"{result.nfev}  wall {result.timings['wall_seconds']:.1f} s")
    if len(result.stages) > 1:
        for st in result.stages:
            print("  " + format_stage(st))
    for miss in summary["breakdown"]["misses"]:
        print(f"  {format_misses([miss])}")
    if "physical" in summary["breakdown"]:
        print(f"  {format_physical(summary['breakdown']['physical'])}")
    if "effort" in summary["breakdown"]:
        print(f"  {format_effort(summary['breakdown']['effort'])}")
    print(f"  result written to {out}/{RESULT} and summary.json")


def hint(result, spec) -> None:
    """What to try after a run that did not converge: options it does not use yet, and the
    gradient only where the search's end puts it in question."""
    if result.status == LIMIT:
        print(f"  hint: raise --maxiter or --time-limit, or continue from this result:\n"
              f"    {command_line(spec, 'solve')} --out {spec.out} --resume {spec.out}")
    if result.status != FAILED:
        return
    asked = spec.settings
    tries = [text for used, text in (
        (asked.rounds, "--rounds N (the keyframes held hard)"),
        (asked.shooting, "--segments K (multiple shooting)"),
        (asked.method != type(asked).method, "--method ipopt")) if not used]
    if "still missed" in result.message and tries:
        print(f"  hint: try {', or '.join(tries)}")
    if "gradient" in result.message:
        route = spec.settings.gradient
        instead = "" if route.exact else f"; --gradient {DEFAULT.name} is exact at the same cost"
        print(f"  hint: '{command_line(spec, 'gradcheck')}' measures the gradient and how far "
              f"its linear model holds{instead}")


def command_line(spec, command: str) -> str:
    """``casadi-keyframe COMMAND PROBLEM --set ...`` for this run's problem and overrides (and,
    for ``solve``, its method and gradient route, so a resumed run goes on the same way)."""
    sets = "".join(f" --set {k}={set_value(v)}" for k, v in spec.overrides.items())
    if command == "solve":
        asked = spec.settings
        sets += f" --method {asked.method} --gradient {asked.gradient.name}" + "".join(
            f" --option {k}={set_value(v)}" for k, v in given_options(asked.options).items())
    return f"casadi-keyframe {command} {spec.problem_arg or spec.problem_file}{sets}"


def left_on_disk(done, spec) -> str:
    """What a second interrupt leaves on disk."""
    out = spec.out
    if done.written:
        return (f"while drawing: the result is in {out}/{RESULT}; draw the pictures with "
                f"'casadi-keyframe render {out}'")
    if done.started and (Path(out) / CHECKPOINT).is_file():
        return (f"before the result was written: the best controls so far are in "
                f"{out}/{CHECKPOINT}; draw them with 'casadi-keyframe render {out}' or "
                f"continue with '{command_line(spec, 'solve')} --out {out} --resume {out}'")
    return "before the first iteration: nothing new written"
