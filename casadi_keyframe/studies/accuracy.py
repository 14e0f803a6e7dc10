"""What the paper's approximations cost, measured: the studies behind the notebooks and
``casadi-keyframe study``.

* :func:`one_step_gap`: one linearized backward Euler step against the full (Newton) step
  from the same state, for a range of dt; the paper says the difference is O(dt^3).
* :func:`gradient_accuracy`: the swapped adjoint against the exact gradient of the same
  linearized scheme on a small cloth in ground contact, varying dt, stiffness and horizon;
  a flock's hand adjoint against CasADi reverse mode as the control case (exact).

Set ``CASADI_KEYFRAME_QUICK=1`` (or pass ``quick=True``) for small, fast versions that the
test suite runs so the notebooks cannot rot.
"""
from __future__ import annotations

import os

import numpy as np

from ..adjoints import Adjoint, CasADiReverse, Swapped
from ..integrators import BackwardEuler, LinearizedBackwardEuler
from ..scenes.flock_path import flock_path_problem
from ..scenes.sheets import contact_problem, hanging_sheet
from ..simulate import simulate


def quick_mode() -> bool:
    """True when ``CASADI_KEYFRAME_QUICK`` is set to anything but 0 (small, fast studies)."""
    return os.environ.get("CASADI_KEYFRAME_QUICK", "0") not in ("", "0")


def fitted_order(h, errors) -> float:
    """Slope of ``log(error)`` against ``log(h)`` by least squares."""
    return float(np.polyfit(np.log(np.asarray(h, float)), np.log(np.asarray(errors, float)), 1)[0])


def relative_error_and_cosine(g, reference) -> tuple[float, float]:
    """``(|g - reference| / |reference|, cosine of the angle between them)``: how far a
    gradient is from a reference gradient, in size and in direction."""
    norm = np.linalg.norm(reference)
    return (float(np.linalg.norm(g - reference) / max(norm, 1e-300)),
            float(g @ reference / max(np.linalg.norm(g) * norm, 1e-300)))


def swapped_vs_exact(dt: float, horizon: float = 1 / 3, stretch: float = 500.0,
                     amplitude: float = 1.0, seed: int = 0) -> dict:
    """One row: the swapped adjoint against the exact hand adjoint (which equals CasADi's
    reverse mode, see the tests) at random forces of ``amplitude`` m/s^2 rms per particle."""
    prob = contact_problem(dt, horizon, stretch)
    rng = np.random.default_rng(seed)
    forces = amplitude * rng.standard_normal((prob.steps, prob.model.n, 3))
    u = (forces * prob.model.masses[:, None]).ravel()
    rel, cos = relative_error_and_cosine(Swapped()(prob, u)[1], Adjoint()(prob, u)[1])
    return {"system": "cloth 5x5", "dt": dt, "steps": prob.steps, "stretch": stretch,
            "relative_error": rel, "cosine": cos}


def flock_control_case(steps: int = 30, dt: float = 0.1, seed: int = 0) -> dict:
    """The control case: a 10-agent flock's hand adjoint (symplectic Euler, eq. 8) against
    CasADi reverse mode; exact, so its error is round-off."""
    prob = flock_path_problem(agents=10, steps=steps, dt=dt, seed=seed)
    u = 0.5 * np.random.default_rng(seed).standard_normal(prob.size)
    rel, cos = relative_error_and_cosine(Adjoint()(prob, u)[1], CasADiReverse()(prob, u)[1])
    return {"system": "flock 10", "dt": dt, "steps": steps, "stretch": float("nan"),
            "relative_error": rel, "cosine": cos}


def gradient_accuracy(quick: bool | None = None) -> dict:
    """The swapped adjoint's error against dt (fixed 1/3 s horizon), stretch stiffness (dt
    1/60) and horizon (dt 1/60), plus the flock control case; each as a list of rows, and
    the fitted order in dt."""
    quick = quick_mode() if quick is None else quick
    dts = [1 / 30, 1 / 60, 1 / 120] if quick else [1 / 30, 1 / 60, 1 / 120, 1 / 240, 1 / 480]
    stretches = [50.0, 500.0] if quick else [50.0, 200.0, 500.0, 2000.0, 5000.0]
    horizons = [1 / 6, 1 / 3] if quick else [1 / 6, 1 / 3, 2 / 3, 4 / 3]
    by_dt = [swapped_vs_exact(dt) for dt in dts]
    return {
        "dt": by_dt,
        "order": fitted_order(dts, [r["relative_error"] for r in by_dt]),
        "stiffness": [swapped_vs_exact(1 / 60, stretch=k) for k in stretches],
        "horizon": [swapped_vs_exact(1 / 60, horizon=h) for h in horizons],
        "control": [flock_control_case(steps=10 if quick else 30)],
    }


def one_step_gap(dts=None, stretch: float = 500.0, rows: int = 5, seed: int = 0,
                 quick: bool | None = None) -> dict:
    """Largest position and velocity differences after one step, linearized vs full
    backward Euler, from a perturbed moving state of :func:`hanging_sheet` (no ground), with
    slopes fitted over all dts and over the finest half (where ``omega dt``, omega the
    fastest stretch frequency, is small and the behaviour asymptotic)."""
    quick = quick_mode() if quick is None else quick
    if dts is None:
        dts = 1 / 30 * 0.5 ** np.arange(4 if quick else 7)
    sheet = _moving_sheet(stretch, rows, seed)
    gaps = [_one_step(*sheet, dt) for dt in dts]
    gap_x, gap_v = [g[0] for g in gaps], [g[1] for g in gaps]
    fine = slice(-(len(dts) // 2) - 1, None)
    omega = np.sqrt(stretch / sheet[0].masses.min())
    dts = np.asarray(dts, float)
    return {"dt": dts.tolist(), "gap_x": gap_x, "gap_v": gap_v,
            "omega_dt": (omega * dts).tolist(),
            "slope_x": fitted_order(dts[fine], gap_x[fine]),
            "slope_v": fitted_order(dts[fine], gap_v[fine]),
            "slope_x_all": fitted_order(dts, gap_x), "slope_v_all": fitted_order(dts, gap_v)}


def one_step_point(dt: float, stretch: float = 500.0, rows: int = 5, seed: int = 0) -> dict:
    """One row of :func:`one_step_gap`: the gaps at one ``dt`` (a sweep's point; the sweep
    fits no slope, its table holds the gaps to fit)."""
    sheet = _moving_sheet(stretch, rows, seed)
    gap_x, gap_v = _one_step(*sheet, dt)
    omega = np.sqrt(stretch / sheet[0].masses.min())
    return {"dt": dt, "omega_dt": float(omega * dt), "gap_x": gap_x, "gap_v": gap_v}


def _moving_sheet(stretch: float, rows: int, seed: int):
    """The hanging sheet (no ground) and a perturbed moving state of it: model, x0, v0."""
    model = hanging_sheet(rows, stretch, ground=False)
    rng = np.random.default_rng(seed)
    x0 = model.rest_positions + 0.02 * rng.standard_normal((model.n, 3))
    v0 = 0.3 * rng.standard_normal((model.n, 3))
    return model, x0, v0


def _one_step(model, x0, v0, dt: float) -> tuple[float, float]:
    """Largest position and velocity difference after one step of size ``dt``."""
    e = np.zeros((1, model.n, 3))
    full = simulate(BackwardEuler(), model, x0, v0, e, dt)
    linear = simulate(LinearizedBackwardEuler("direct"), model, x0, v0, e, dt)
    return (float(np.abs(full.x[1] - linear.x[1]).max()),
            float(np.abs(full.v[1] - linear.v[1]).max()))


def format_one_step_gap(gap: dict) -> str:
    """The printed form of :func:`one_step_gap`."""
    lines = ["One step, linearized vs full backward Euler (5x5 sheet, stretch 500 N/m):",
             f"  {'dt':>8s} {'omega dt':>9s} {'max |dx| m':>11s} {'max |dv| m/s':>13s}"]
    for dt, w, gx, gv in zip(gap["dt"], gap["omega_dt"], gap["gap_x"], gap["gap_v"]):
        lines.append(f"  {'1/%d' % round(1 / dt):>8s} {w:9.3f} {gx:11.3e} {gv:13.3e}")
    lines.append(f"  fitted slope, positions: {gap['slope_x']:.2f} (finest half), "
                 f"{gap['slope_x_all']:.2f} (all)")
    lines.append(f"  fitted slope, velocities: {gap['slope_v']:.2f} (finest half), "
                 f"{gap['slope_v_all']:.2f} (all)")
    return "\n".join(lines)


def format_rows(rows, title: str) -> str:
    """A plain-text table of study rows."""
    lines = [title, f"  {'system':10s} {'dt':>8s} {'steps':>6s} {'stretch':>8s} "
                    f"{'rel. error':>11s} {'cosine':>9s}"]
    for r in rows:
        lines.append(f"  {r['system']:10s} {'1/%d' % round(1 / r['dt']):>8s} {r['steps']:6d} "
                     f"{r['stretch']:8.0f} {r['relative_error']:11.3e} {r['cosine']:9.5f}")
    return "\n".join(lines)


def format_gradient_accuracy(study: dict) -> str:
    """The printed form of :func:`gradient_accuracy`."""
    return "\n".join([
        "Swapped adjoint vs exact gradient of the linearized scheme (5x5 sheet, ground contact)",
        format_rows(study["dt"], "by time step, horizon 1/3 s:"),
        f"  fitted order in dt: {study['order']:.2f}",
        format_rows(study["stiffness"], "by stretch stiffness (N/m), dt 1/60:"),
        format_rows(study["horizon"], "by horizon, dt 1/60:"),
        format_rows(study["control"], "control case, flock hand adjoint vs CasADi reverse mode:"),
    ])


def convergence_runs(runs, maxiter: int) -> dict:
    """Solve each ``(label, problem, method, gradient)`` from the problem's start and keep
    its convergence: objective per iteration and seconds, final objective, iterations, wall
    seconds (a failed run keeps its message instead of stopping the study)."""
    from ..optimize import solve
    out = {}
    for label, problem, method, gradient in runs:
        start = problem.objective(problem.initial_controls())
        try:
            result = solve(problem, method, gradient=gradient, maxiter=maxiter, quiet=True)
        except Exception as err:  # noqa: BLE001 - a study reports failures, it does not stop
            out[label] = {"error": f"{type(err).__name__}: {err}"}
            continue
        h = result.history
        out[label] = {"iteration": [0] + [r["iteration"] for r in h],
                      "objective": [start] + [r["objective"] for r in h],
                      "seconds": [0.0] + [r["seconds"] for r in h],
                      "final": result.fun, "nit": result.nit, "nfev": result.nfev,
                      "wall": result.timings["wall_seconds"], "message": result.message}
    return out


def format_convergence(runs: dict, title: str) -> str:
    """A plain-text table of :func:`convergence_runs`."""
    lines = [title, f"  {'run':34s} {'final objective':>15s} {'iterations':>10s} "
                    f"{'evaluations':>11s} {'seconds':>8s}"]
    for label, r in runs.items():
        if "error" in r:
            lines.append(f"  {label:34s} failed: {r['error']}")
        else:
            lines.append(f"  {label:34s} {r['final']:15.6g} {r['nit']:10d} {r['nfev']:11d} "
                         f"{r['wall']:8.1f}")
    return "\n".join(lines)
