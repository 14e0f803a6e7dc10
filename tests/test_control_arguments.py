"""ControlProblem's methods refuse controls that are not a flat vector of real numbers with
the library's own message (before CasADi sees them): None, text, complex numbers, booleans,
objects, ragged lists, the wrong length or shape, NaN."""
import numpy as np
import pytest

from casadi_keyframe import load_problem, solve


@pytest.fixture(scope="module")
def prob():
    return load_problem("flock_path", agents=4, steps=10)


def bad_controls(n):
    """(controls, exception, words of the message)."""
    return {
        "None": (None, TypeError, "got None"),
        "complex": (np.zeros(n, complex), TypeError, "got complex numbers: pass the real part"),
        "strings": (["a"] * n, TypeError, "got text of dtype <U1"),
        "a string": ("zeros", TypeError, "got 'zeros'"),
        "booleans": (np.zeros(n, bool), TypeError, "got booleans"),
        "Nones": ([None] * n, TypeError, "got Python objects that are not numbers (e.g. None)"),
        "a dict": ({"u": 1}, TypeError, "got Python objects that are not numbers"),
        "ragged": ([[1.0, 2.0], [3.0]], TypeError, "got a ragged list"),
        "short": (np.zeros(n - 1), ValueError, f"got shape ({n - 1},)"),
        "a column": (np.zeros((n, 1)), ValueError, f"got shape ({n}, 1)"),
        "NaN": (np.full(n, np.nan), ValueError, "controls contain NaN or inf"),
    }


METHODS = {
    "objective": lambda p, u: p.objective(u),
    "objective_and_gradient": lambda p, u: p.objective_and_gradient(u),
    "directional_derivative": lambda p, u: p.directional_derivative(p.initial_controls(), u),
    "breakdown": lambda p, u: p.breakdown(u),
    "control_cost": lambda p, u: p.control_cost(u),
    "simulate": lambda p, u: p.simulate(u),
    "solve(u0=)": lambda p, u: solve(p, u0=u, maxiter=1, quiet=True),
}


@pytest.mark.parametrize("method", METHODS)
def test_bad_controls_get_the_librarys_message(prob, method):
    for name, (u, kind, words) in bad_controls(prob.size).items():
        if u is None and method in ("simulate", "solve(u0=)"):
            continue  # None means the passive controls (simulate) or the problem's start
        with pytest.raises(kind) as err:
            METHODS[method](prob, u)
        text = str(err.value)
        assert words in text, (method, name, text)
        assert f"a flat vector of {prob.size} real numbers (10 x 4 x 2)" in text or "NaN" in text
        assert "Function_call" not in text and "overloaded" not in text


def test_good_controls_of_every_real_kind_are_taken(prob):
    n = prob.size
    reference = prob.objective(np.zeros(n))
    for u in (np.zeros(n, int), [0] * n, np.zeros(n, np.float32), np.zeros(n, object)):
        assert prob.objective(u) == reference


def test_solve_refuses_a_negative_tolerance_before_simulating(prob, monkeypatch):
    monkeypatch.setattr(type(prob), "simulate", lambda *a, **k: pytest.fail("simulated"))
    with pytest.raises(ValueError, match="tol must be a finite number > 0 .* got -1"):
        solve(prob, tol=-1, quiet=True)
