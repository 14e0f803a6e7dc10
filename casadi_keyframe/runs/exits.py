"""How a run ends, as a command's exit code: the codes (:data:`EXIT_CODES`), and work run
under SIGINT and SIGTERM (:func:`guarded`), which stop it the same way."""
from __future__ import annotations

import signal

from ..interrupts import NAMES, catching
from ..optimize.outcome import CONVERGED, FAILED, INTERRUPTED, LIMIT

EXIT_CODES = """\
exit codes:
  0    converged: every keyframe within its tolerance; result and pictures written
  1    the search failed: the method stopped short of the goal (line search, no further
       decrease, IPOPT error...), the keyframes missed named, the best point still
       written; or the simulation fails at the start (nothing written)
  2    bad input (problem, overrides, options, --resume source)
  3    stopped at --maxiter or --time-limit before converging; result written: raise the
       limit or continue with --resume OUT
  130  interrupted by Ctrl-C (SIGINT); result written, pictures skipped ('render OUT')
  143  stopped by SIGTERM; as 130"""
_EXIT = {CONVERGED: 0, FAILED: 1, LIMIT: 3}
_SIGNAL_EXIT = {signal.SIGINT: 130, signal.SIGTERM: 143}


def exit_code(status: int, signum: int | None = None) -> int:
    """The command's exit code for a result ``status`` (and the signal that stopped it)."""
    if status == INTERRUPTED:
        return _SIGNAL_EXIT.get(signum or signal.SIGINT, 128 + (signum or 2))
    return _EXIT[status]


def guarded(work, stopped) -> int:
    """``work(caught)``'s exit code, or, when SIGINT or SIGTERM stops it, ``stopped(signum)``
    printed and the signal's exit code."""
    with catching() as caught:
        try:
            return work(caught)
        except Exception:  # raised inside C code, a signal can surface as another error
            if caught.signum is None:
                raise
            signum = caught.signum
        except KeyboardInterrupt as err:
            signum = getattr(err, "signum", signal.SIGINT)
        print(stopped(signum))
        return exit_code(INTERRUPTED, signum)


def stopped(signum) -> str:
    signum = signum or signal.SIGINT
    return "interrupted (Ctrl-C)" if signum == signal.SIGINT else f"stopped by {NAMES.get(signum, signum)}"
