"""The ``casadi-keyframe`` command line: list, show, solve, render, export and gradcheck
problems; sweep a problem over a grid of overrides; print studies or run their grids."""
from __future__ import annotations

import sys
import traceback

from ..export.alembic import BlenderError
from ..loading import OverrideError, ProblemFileError
from ..optimize.outcome import INTERRUPTED
from ..runs import exit_code
from ..state import SimulationError
from .parser import build_parser

def main(argv=None) -> int:
    """Run a command: 0 on success, 1 when the simulation fails, 2 on bad input (a message,
    never a traceback; ``--debug`` adds the traceback)."""
    args = build_parser().parse_args(argv)
    debug = getattr(args, "debug", False)
    try:
        return args.func(args)
    except OverrideError as err:
        _error(err, debug, f"\n  'casadi-keyframe show {err.problem}' lists the overrides "
                           "with their types, defaults and ranges" if err.listed else "")
        return 2
    except SimulationError as err:
        text = " ".join(str(err).split())
        text = text if "simulation" in text else f"the simulation failed: {text}"
        fix = "" if "reduce" in text else "; reduce dt (--set dt=...) or the forces"
        _error(err, debug, text=text + fix)
        return 1
    except ProblemFileError as err:
        _error(err, debug, "" if debug else "\n  (--debug shows the whole traceback)")
        return 2
    except (ValueError, TypeError, FileNotFoundError, ImportError) as err:
        _error(err, debug)
        return 2
    except BlenderError as err:  # an export through Blender that Blender did not finish
        _error(err, debug)
        return 1
    except KeyboardInterrupt:  # a Ctrl-C outside the guarded work (its files are whole)
        return exit_code(INTERRUPTED)


def _error(err, debug: bool, more: str = "", *, text: str | None = None) -> None:
    """``error: MESSAGE`` on stderr (with ``--debug``, the traceback first)."""
    if debug:
        traceback.print_exception(err)
    print(f"error: {err if text is None else text}{more}", file=sys.stderr)

