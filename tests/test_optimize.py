"""Optimizers: L-BFGS-B and IPOPT agree, bounds hold, Ctrl-C keeps the best result, and the
status says how a search ended."""
import os
import signal
import threading
import time
from dataclasses import dataclass, replace
from typing import ClassVar

import numpy as np
import pytest

from casadi_keyframe import Adjoint, SimulationError, load_problem, solve
from casadi_keyframe.saved import Checkpoint, read_run
from casadi_keyframe.optimize import CONVERGED, FAILED, INTERRUPTED, LIMIT
from casadi_keyframe.optimize.methods import TypedOptions

from helpers import InterruptAfter


@pytest.fixture(scope="module")
def race():
    return load_problem("flock_race", agents=8, steps=40)


def test_lbfgsb_and_ipopt_reach_the_same_objective(race):
    a = solve(race, "lbfgsb", maxiter=150, quiet=True, stop="method")
    b = solve(race, "ipopt", maxiter=150, quiet=True, stop="method")
    passive = race.objective(race.initial_controls())
    assert a.fun < 1e-2 * passive and b.fun < 1e-2 * passive
    assert b.fun == pytest.approx(a.fun, rel=0.05)
    for r in (a, b):
        assert r.nit == len(r.history) and r.nit > 0
        assert {"objective", "keyframe_error", "control_norm", "seconds"} <= set(r.history[0])
        assert r.fun == pytest.approx(race.objective(r.x), rel=1e-12)
        assert r.trajectory.x.shape == (41, 8, 2)


def test_ipopt_holds_equality_constraints_given_with_a_sparse_jacobian():
    """The Callbacks multiple shooting's defects go through, on a problem with a known
    answer: min |x|^2 with x0 + x1 = 1 and x2 - 2 x3 = 1."""
    import casadi as ca
    import scipy.sparse as sp

    from casadi_keyframe.optimize.deadline import Deadline
    from casadi_keyframe.optimize.methods.ipopt import search

    def ev(x):
        return float(x @ x), 2 * x

    ev.interrupted = None

    class Lines:
        size = 2
        pattern = ca.Sparsity.triplet(2, 4, [0, 0, 1, 1], [0, 1, 2, 3])

        def values(self, x):
            return np.array([x[0] + x[1] - 1, x[2] - 2 * x[3] - 1])

        def jacobian(self, x):
            return sp.csc_matrix([[1.0, 1.0, 0, 0], [0, 0, 1.0, -2.0]])

    seen = []
    free = (np.full(4, -np.inf), np.full(4, np.inf))
    status, message, x = search(ev, np.zeros(4), free, 50, 1e-10, {}, seen.append,
                                Deadline.start(), constraints=Lines())
    assert status == CONVERGED, message
    assert seen and all(s.shape == (4,) for s in seen)  # each iterate handed over
    np.testing.assert_allclose(x, [0.5, 0.5, 0.2, -0.4], atol=1e-8)


@pytest.mark.parametrize("method", ["lbfgsb", "ipopt"])
def test_bounds_are_respected(race, method):
    prob = load_problem("flock_race", agents=8, steps=40)
    prob.controls.lower, prob.controls.upper = -0.5, 0.5
    r = solve(prob, method, maxiter=50, quiet=True)
    assert np.abs(r.x).max() <= 0.5 + 1e-9
    assert np.abs(r.x).max() > 0.4  # the bound is active: the problem wants more force


@pytest.mark.parametrize("method", ["lbfgsb", "ipopt"])
def test_interrupt_returns_and_saves_the_best_result(race, method, tmp_path):
    ckpt = tmp_path / "best.npz"
    r = solve(race, method, gradient=InterruptAfter(12), maxiter=500, quiet=True,
              checkpoint=ckpt)
    assert "interrupted" in r.message and not r.success and r.status == INTERRUPTED
    saved = np.load(ckpt)
    assert saved["fun"] <= race.objective(race.initial_controls())
    assert r.fun <= float(saved["fun"]) + 1e-12
    assert r.fun == pytest.approx(race.objective(r.x), rel=1e-12)


def test_failed_simulations_during_the_search_are_counted_not_returned(race):
    class Fails(Adjoint):
        count = 0

        def evaluate(self, problem, u):
            Fails.count += 1
            if Fails.count in (3, 4):
                raise SimulationError("blew up", 1)
            return super().evaluate(problem, u)

    r = solve(race, gradient=Fails(), maxiter=30, quiet=True)
    assert r.timings["failed_simulations"] >= 1 and np.isfinite(r.fun)
    # and the search goes on past them (an infinite objective made L-BFGS-B give up)
    assert r.nit > 10 and r.fun < 0.2 * race.objective(race.initial_controls())


class Counting(Adjoint):
    calls = 0

    def evaluate(self, problem, u):
        Counting.calls += 1
        return super().evaluate(problem, u)


@pytest.mark.parametrize("kwargs, message", [
    ({"method": "newton"}, "unknown method 'newton'; choose one of lbfgsb, ipopt"),
    ({"maxiter": 2.5}, "maxiter must be a whole number >= 1"),
    ({"maxiter": 0}, "maxiter must be a whole number >= 1"),
    ({"maxiter": True}, "maxiter must be a whole number >= 1"),
    ({"tol": 0.0}, "tol must be a finite number > 0"),
    ({"tol": float("nan")}, "tol must be a finite number > 0"),
    ({"tol": float("inf")}, "tol must be a finite number > 0"),
    ({"time_limit": 0}, "time_limit must be a finite positive number of seconds"),
    ({"time_limit": float("inf")}, "time_limit must be a finite positive number of seconds"),
    ({"time_limit": "60"}, "time_limit must be a finite positive number of seconds"),
    ({"options": {"maxcorr": 5}}, r"options for method 'lbfgsb': unknown option 'maxcorr' "
                                  r"\(did you mean 'maxcor'\?\); scipy's L-BFGS-B takes .*maxls"),
    ({"method": "ipopt", "options": {"max_itr": 5}},
     r"unknown option 'max_itr' \(did you mean 'max_iter'.*listed by "
     r"casadi_keyframe.optimize.methods.ipopt.option_names\(\)"),
    ({"method": "ipopt", "options": {"hessian_approximation": "exakt"}},
     r"(?s)IPOPT refuses option 'hessian_approximation' = 'exakt'.*limited-memory"),
    ({"method": "ipopt", "options": {"max_iter": "ten"}},
     "IPOPT option 'max_iter' must be a whole number"),
])
def test_bad_settings_are_refused_before_any_simulation(race, kwargs, message):
    Counting.calls = 0
    with pytest.raises(ValueError, match=message):
        solve(race, gradient=Counting(), quiet=True, **kwargs)
    assert Counting.calls == 0


@pytest.mark.parametrize("method, options", [
    ("lbfgsb", {"maxls": 30, "maxcor": 5}),
    ("ipopt", {"limited_memory_max_history": 5, "sb": "yes"}),  # sb: known, undocumented
])
def test_valid_options_reach_the_method(race, method, options):
    r = solve(race, method, maxiter=3, quiet=True, options=options)
    assert r.nit == 3 and r.status == LIMIT


def test_option_names_are_read_from_the_libraries():
    from casadi_keyframe.optimize.methods import ipopt, lbfgsb

    assert {"maxcor", "ftol", "gtol", "maxfun", "maxiter", "maxls"} <= set(lbfgsb.option_names())
    assert {"tol", "max_iter", "hessian_approximation", "limited_memory_max_history",
            "max_wall_time"} <= set(ipopt.option_names())
    assert "sb" not in ipopt.option_names()  # undocumented: IPOPT itself is asked (above)


@dataclass(frozen=True)
class DescentOptions(TypedOptions):
    """A method's own typed options, as the transcription's ``start=rest|blend|zero`` are."""

    label: ClassVar[str] = "descent"
    CHECKS: ClassVar[dict] = {"step": ("a number > 0", lambda v: v > 0)}
    step: float = 1e-3


def descend(problem, ev, u0, call):
    """Gradient steps whose trial halfway is judged without a gradient (``ev.offer``: kept
    if it is the best point), until ``call.deadline`` passes."""
    u = u0
    for _ in range(call.maxiter):
        if call.deadline.passed():
            return LIMIT, "time limit reached"
        f, g = ev(u)
        ev.offer(u - 0.5 * call.options.step * g)
        u = u - call.options.step * g
        call.on_iteration()
    return LIMIT, f"{call.maxiter} steps taken"


def test_solve_dispatches_through_the_method_table(race, monkeypatch, tmp_path, capsys):
    """A new method is one entry of METHODS (the way the transcription comes in): solve runs
    it with the evaluator, the one deadline and its own typed options, from the settings or
    the command line's --option, checked against its names before anything is built; the
    points it offers without a gradient are judged and kept like any other; its iterations
    land in the history."""
    from casadi_keyframe.cli import main
    from casadi_keyframe.optimize import METHODS, Method

    monkeypatch.setitem(METHODS, "descent", Method("descent", descend, DescentOptions))
    r = solve(race, "descent", maxiter=4, quiet=True, options={"step": 1e-4})
    assert r.method == "descent" and r.nit == 4 and r.status == LIMIT
    assert r.fun < race.objective(race.initial_controls())
    assert (r.njev, r.nfev) == (4, 8)  # the start (memoised) and four offers, no gradient
    assert r.fun == pytest.approx(race.objective(r.x), rel=1e-12)
    with pytest.raises(ValueError, match="did you mean 'step'"):
        solve(race, "descent", quiet=True, options={"stepp": 1e-4})
    with pytest.raises(ValueError, match="descent option 'step' must be a number > 0"):
        solve(race, "descent", quiet=True, options={"step": -1.0})
    small = ["solve", "flock_race", "--set", "agents=8", "--set", "steps=40", "--quiet",
             "--no-animation", "--no-viewer", "--method", "descent", "--out", str(tmp_path)]
    assert main([*small, "--maxiter", "2", "--option", "step=1e-4"]) == 3
    assert main([*small, "--option", "stepp=1e-4"]) == 2
    assert "unknown option 'stepp' (did you mean 'step'?)" in capsys.readouterr().err


def test_the_command_line_offers_the_method_table():
    from casadi_keyframe.cli import build_parser
    from casadi_keyframe.optimize import METHODS

    parser = build_parser()
    for command in (["solve", "flock_race"], ["sweep", "flock_race", "--grid", "agents=4"]):
        for name in METHODS:
            assert parser.parse_args(command + ["--method", name]).method == name
        with pytest.raises(SystemExit):
            parser.parse_args(command + ["--method", "newton"])


class WrongSign(Adjoint):
    """The gradient's opposite: every search direction climbs."""

    def evaluate(self, problem, u):
        found = super().evaluate(problem, u)
        return replace(found, gradient=-found.gradient)


class Slow(Adjoint):
    def evaluate(self, problem, u):
        time.sleep(0.05)
        return super().evaluate(problem, u)


def test_the_status_says_how_the_search_ended(race):
    done = solve(race, maxiter=300, quiet=True)
    assert done.status == CONVERGED and done.success and done.message.startswith("converged")
    for method in ("lbfgsb", "ipopt"):
        r = solve(race, method, maxiter=3, quiet=True)
        assert r.status == LIMIT and not r.success and r.nit == 3
        assert r.message.startswith("iteration limit reached (3 iterations in this stage) before converging")
        assert r.summary()["status"] == LIMIT and r.summary()["status_name"] == "limit reached"


def test_a_failed_line_search_says_why_not_abnormal():
    prob = load_problem("flock_path", agents=6, steps=20)
    r = solve(prob, gradient=WrongSign(), maxiter=50, quiet=True)
    assert r.status == FAILED and not r.success  # scipy's bare "ABNORMAL: ", translated
    assert r.message.startswith("line search failed") and "gradient may be inaccurate" in r.message
    assert r.fun <= prob.objective(prob.initial_controls())  # still the best point seen


@pytest.mark.parametrize("method", ["lbfgsb", "ipopt"])
def test_the_time_limit_stops_the_search_with_status_limit(race, method):
    t = time.perf_counter()
    r = solve(race, method, gradient=Slow(), maxiter=500, quiet=True, time_limit=0.5)
    assert time.perf_counter() - t < 3.0
    assert r.status == LIMIT and r.message.startswith("time limit reached (0.5 s)")
    assert r.nit >= 1 and r.fun < race.objective(race.initial_controls())
    with pytest.raises(ValueError, match="time_limit"):
        solve(race, method, time_limit=0)


def test_ctrl_c_inside_ipopt_is_an_interrupt_not_an_ipopt_error(race):
    """A real SIGINT, sent while IPOPT runs: it used to end as NonIpopt_Exception_Thrown
    (4 runs of 5, measured) or go unnoticed (IPOPT ran on to its 500 iterations)."""
    class SignalAt(Adjoint):
        calls = 0

        def evaluate(self, problem, u):
            SignalAt.calls += 1
            if SignalAt.calls == 8:
                threading.Timer(0.002, os.kill, (os.getpid(), signal.SIGINT)).start()
            return super().evaluate(problem, u)

    r = solve(race, "ipopt", gradient=SignalAt(), maxiter=500, quiet=True)
    assert r.status == INTERRUPTED and r.message.startswith("interrupted by user (SIGINT)")
    assert r.nit >= 1 and r.fun == pytest.approx(race.objective(r.x), rel=1e-12)


def test_the_checkpoint_is_enough_to_resume_and_written_whole(race, tmp_path):
    ckpt = Checkpoint(tmp_path / "checkpoint.npz", problem="flock_race",
                      overrides={"agents": 8, "steps": 40})
    r = solve(race, maxiter=5, quiet=True, checkpoint=ckpt)
    saved = read_run(tmp_path)
    assert saved["meta"]["problem"] == "flock_race" and saved["meta"]["nit"] == r.nit == 5
    assert saved["meta"]["overrides"] == {"agents": 8, "steps": 40}
    assert saved["meta"]["stage"] == 0 and saved["u"].size == race.size
    assert saved["meta"]["fun"] == pytest.approx(r.fun)
    assert [p.name for p in tmp_path.iterdir()] == ["checkpoint.npz"]  # no temporaries
    again = solve(race, maxiter=1, quiet=True, u0=saved["u"])
    assert again.fun <= r.fun


def test_a_line_search_failure_is_converged_only_when_the_goal_is_met(monkeypatch):
    """After progress, L-BFGS-B restarts once from its best point with no curvature memory;
    if not even that steepest-descent step lowers phi, the search stops (at a kink or the
    round-off floor).  That is "converged" only with every keyframe within its tolerance;
    otherwise it failed (status 2) and says which keyframes it misses and by how much.  A
    failure at the very first step stays a failure too."""
    import casadi_keyframe.optimize.methods.lbfgsb as lbfgsb
    from scipy.optimize import OptimizeResult

    starts = []

    def scripted(nits):
        def minimize(fun, x0, **kw):
            starts.append(np.array(x0))
            fun(x0)
            if len(starts) == 1:
                fun(x0 - 1e-3 * fun(x0)[1])  # some progress: a better best point
            return OptimizeResult(message="ABNORMAL: ", nit=nits[len(starts) - 1], nfev=3)
        return minimize

    monkeypatch.setattr(lbfgsb, "minimize", scripted([3, 0]))
    prob = load_problem("flock_path", agents=6, steps=20)  # keyframes within 0.15 by default
    r = solve(prob, maxiter=50, quiet=True)
    assert len(starts) == 2 and np.array_equal(starts[1], r.x)  # restarted at the best
    assert r.status == FAILED and not r.success
    assert "no step along the steepest descent" in r.message
    far = [m for m in r.breakdown["misses"] if m["position_error"] > 0.15]
    assert far and all(f"{m['term']}: position miss {m['position_error']:.3g} (tolerance 0.15)"
                       in r.message for m in far)
    starts.clear()
    loose = load_problem("flock_path", agents=6, steps=20, tolerance=100.0)
    r = solve(loose, maxiter=50, quiet=True, stop="method")  # met, but run the method
    assert len(starts) == 2 and r.status == CONVERGED and r.success
    assert r.message.startswith("converged: every keyframe within its tolerance (then the "
                                "method stopped: line search failed: no step along the "
                                "steepest descent")
    assert "inaccurate" not in r.message  # the gradient is not in question where it converged
    starts.clear()
    monkeypatch.setattr(lbfgsb, "minimize", scripted([0, 0]))
    r = solve(prob, maxiter=50, quiet=True)
    assert len(starts) == 1 and r.status == FAILED


def test_a_line_search_failure_off_the_goal_exits_1_and_still_writes_its_best_point(
        monkeypatch, tmp_path, capsys):
    """The command line's side of the same path: status 2 is exit 1, the message names the
    keyframes missed, and result.npz holds the best point."""
    import casadi_keyframe.optimize.methods.lbfgsb as lbfgsb
    from casadi_keyframe.cli import main
    from scipy.optimize import OptimizeResult

    def minimize(fun, x0, **kw):
        fun(x0)
        return OptimizeResult(message="ABNORMAL: ", nit=0, nfev=1)

    monkeypatch.setattr(lbfgsb, "minimize", minimize)
    code = main(["solve", "flock_path", "--set", "agents=6", "--set", "steps=20", "--quiet",
                 "--no-animation", "--no-viewer", "--out", str(tmp_path)])
    out = capsys.readouterr().out
    assert code == 1, out
    said = out.splitlines()[1]
    assert said.startswith("flock_path: line search failed") and "converged" not in said
    assert "still missed: CenterOfMass@2: position miss 3.17 (tolerance 0.15)" in said
    assert said.endswith("CenterOfMass@20: position miss 32.1 (tolerance 0.15)")
    hints = [line for line in out.splitlines() if "hint:" in line]
    assert "--rounds N" in hints[0] and "--segments K" in hints[0] and "--method ipopt" in hints[0]
    assert "gradcheck" in hints[1] and "--gradient" not in hints[1]  # already the exact route
    run = read_run(tmp_path / "result.npz")
    assert run["u"].size == load_problem("flock_path", agents=6, steps=20).size


def test_advice_never_suggests_an_option_in_use(capsys):
    from types import SimpleNamespace

    from casadi_keyframe.runs.report import hint

    failed = SimpleNamespace(status=FAILED, message="search failed: ...; still missed: x")
    from casadi_keyframe.optimize import SolveSettings

    asked = SolveSettings(rounds=3, shooting=4, method="ipopt", gradient="swapped")
    spec = SimpleNamespace(settings=asked, overrides={}, problem_arg="p", out="o")
    hint(failed, spec)
    assert capsys.readouterr().out == ""  # every remedy is in use, the gradient not in question
    failed.message += "; the gradient may be inaccurate"
    hint(failed, spec)
    assert "--gradient adjoint is exact" in capsys.readouterr().out


def test_a_search_stops_once_the_goal_is_met_and_a_miss_is_never_a_success(race):
    r = solve(race, maxiter=300, quiet=True)
    assert r.status == CONVERGED and r.message.startswith("converged: the goal is met at "
                                                          "iteration")
    assert r.nit < 300 and all(m.get("position_error", 0) <= 0.1 for m in r.breakdown["misses"])
    full = solve(race, maxiter=300, quiet=True, stop="method")
    assert full.nit > r.nit  # the method's own test comes later
    tight = load_problem("flock_race", agents=8, steps=40, tolerance=1e-6)
    for method in ("lbfgsb", "ipopt"):
        missed = solve(tight, method, maxiter=300, quiet=True)
        assert missed.status != CONVERGED and "still missed" in missed.message
    with pytest.raises(ValueError, match="stop must be 'goal'"):
        solve(race, stop="always")
