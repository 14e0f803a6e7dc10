r"""Where the paper's swapped adjoint suffices: the map behind ``casadi-keyframe study
swap-validity`` and the last section of ``notebooks/gradient_accuracy.ipynb``.

One point (:func:`swap_validity_point`) is a hanging sheet swung to a keyframe, touching one
kind of contact (:data:`KINDS`: none, the ground, a sliding sphere or capsule, itself), at a
stiffness ``dt sqrt(k/m)`` and a ``collision``; it compares the swapped gradient with the
exact one (cosine, relative error, both backward passes' growth) and, with ``solve``, says
whether L-BFGS-B on the swapped route ``reaches`` the exact route's objective.
:func:`swap_validity` runs the map's slices, :func:`format_swap_validity` prints them,
:func:`reading` says in sentences where the swap suffices.  The scenes and their recipe:
``docs/explanations/swap_validity.md``.
"""
from __future__ import annotations

import warnings
from fractions import Fraction

import numpy as np

from ..adjoints import Adjoint, Swapped
from ..checks import frame_at
from ..controls import StepForces
from ..health import GROWTH_BOUND, GradientRouteWarning, past_bound
from ..integrators import LinearizedBackwardEuler
from ..models import DEFAULT_COLLISION, Capsule, ClothModel, ClothParams, Plane, Sphere
from ..models.contact.colliders import Contact, signed_distances
from ..objectives import CenterOfMassKeyframe, Smoothness, StateKeyframe
from ..problem import ControlProblem
from ..simulate import simulate
from ..state import SimulationError, State
from .accuracy import fitted_order, quick_mode, relative_error_and_cosine

KINDS = ("none", "ground", "sphere", "capsule", "self")
REFERENCE_DT = 1 / 60  # the step at which ``stiffness`` is dt sqrt(k/m)
REACH = 1.1  # the swapped route "reaches" when its objective is at most this times the exact's


def sheet_model(contact: str, *, stiffness: float, collision: str = DEFAULT_COLLISION,
                rows: int = 5, speed: float = 1.0, damping: float = 1.0):
    """``(model, x0)``: the map's sheet touching ``contact`` (module docstring)."""
    if contact not in KINDS:
        raise ValueError(f"contact must be one of {KINDS}, got {contact!r}")
    n = rows * rows
    mass = 1.0 / n  # the mean particle mass of the 1 kg sheet
    k = (stiffness / REFERENCE_DT) ** 2 * mass
    law = Contact(k, damping * k * REFERENCE_DT, thickness=0.012, width=0.006)
    params = ClothParams(stretch=k, shear=k / 10)
    if contact == "self":
        loop = Contact(k, damping * k * REFERENCE_DT, thickness=0.4 / (rows - 1),
                       width=0.2 / (rows - 1))
        model = ClothModel.grid(rows, rows, params=params, self_contact=loop,
                                pinned=[0, rows - 1, n - rows, n - 1])
        return model, _folded(model.rest_positions, rows, gap=0.06)
    model = ClothModel.grid(rows, rows, params=params, pinned=[0, rows - 1],
                            colliders=_bodies(contact, law, speed), collision=collision)
    return model, model.rest_positions


def _bodies(contact: str, law: Contact, speed: float) -> list:
    """The colliders of each kind, for the hanging sheet (top edge at z = 0, 1 m tall)."""
    if contact == "none":
        return []
    if contact == "ground":
        return [Plane((0.0, 0.0, -1.007), contact=law)]
    radius = 0.15 if contact == "sphere" else 0.1
    start = np.array([0.3, 0.03 - radius, -0.55])  # 3 cm into the sheet, from behind

    def centre(t, rise=0.0):
        return start + [speed * t, 0.0, rise]

    if contact == "sphere":
        return [Sphere(centre, radius, contact=law)]
    return [Capsule(lambda t: centre(t, 0.25), lambda t: centre(t, -0.25), radius,
                    contact=law)]


def _folded(x, rows: int, gap: float) -> np.ndarray:
    """The sheet folded at its middle row into a loop: the lower rows go back up behind the
    upper ones, ``gap`` m behind."""
    x = x.copy()
    r = np.arange(len(x)) // rows
    back = r > (rows - 1) / 2
    x[:, 2] = -np.where(back, rows - 1 - r, r) / (rows - 1)
    x[:, 1] = np.where(back, gap, 0.0)
    return x


def sheet_problem(contact: str = "none", *, stiffness: float = 4.0, dt: float = 1 / 60,
                  horizon: float = 1 / 3, **scene) -> ControlProblem:
    """The map's control problem: the sheet from rest, every free particle 20 cm forward
    and 5 cm up at the end, its centre of mass 10 cm forward half way, by smooth step
    forces; ``scene`` as :func:`sheet_model`."""
    model, x0 = sheet_model(contact, stiffness=stiffness, **scene)
    steps = frame_at(horizon, dt, "swap validity: the horizon")
    if steps < 2:
        raise ValueError(f"swap validity: dt = {dt} must divide the horizon {horizon} s into "
                         ">= 2 steps")
    objective = (StateKeyframe(steps, x=x0 + (0.0, 0.2, 0.05))
                 + CenterOfMassKeyframe(steps // 2, x=x0.mean(0) + (0.0, 0.1, 0.0))
                 + Smoothness(1e-4))
    return ControlProblem(model=model, integrator=LinearizedBackwardEuler("direct"), x0=x0,
                          v0=np.zeros_like(x0), steps=steps, dt=dt, controls=StepForces(),
                          objective=objective, name=f"swap_validity_{contact}")


def swap_validity_point(contact: str = "none", collision: str = DEFAULT_COLLISION,
                        stiffness: float = 4.0, dt: float = 1 / 60, amplitude: float = 1.0,
                        horizon: float = 1 / 3, speed: float = 1.0, damping: float = 1.0,
                        rows: int = 5, solve: bool = False, maxiter: int = 40,
                        seed: int = 0, measure: str = "horizon") -> dict:
    """One row of the map (module docstring); a simulation that fails at the random forces
    gives a row of NaNs with its ``reason``.  ``measure="step"``: one backward step instead
    (:func:`one_step_error`; ``horizon``, ``solve`` and ``maxiter`` unused)."""
    if measure == "step":
        return one_step_error(contact, collision, stiffness, dt, amplitude, speed, damping,
                              rows, seed)
    prob = sheet_problem(contact, stiffness=stiffness, dt=dt, horizon=horizon,
                         collision=collision, rows=rows, speed=speed, damping=damping)
    rng = np.random.default_rng(seed)
    forces = amplitude * rng.standard_normal((prob.steps, prob.model.n, 3))
    u = (forces * prob.model.masses[:, None]).ravel()
    mass = prob.model.masses.mean()
    row = {"steps": prob.steps, "omega_dt": float(dt * np.sqrt(prob.model.params.stretch / mass))}
    exact, swapped = Adjoint(guard=False), Swapped(guard=False)
    try:
        with np.errstate(all="ignore"), warnings.catch_warnings():
            warnings.simplefilter("ignore", GradientRouteWarning)  # the row says it
            exact, swapped = exact.evaluate(prob, u), swapped.evaluate(prob, u)
            rel, cos = relative_error_and_cosine(swapped.gradient, exact.gradient)
        row["touching"] = touching(prob, prob.simulate(u).x)
    except SimulationError as err:
        return {**row, **dict.fromkeys(FIGURES, np.nan), "reason": str(err)}
    row.update({"cosine": cos, "relative_error": rel, "growth_swapped": swapped.growth.growth,
                "growth_exact": exact.growth.growth,
                "refused": past_bound(swapped.growth.growth, GROWTH_BOUND)})
    if solve:
        row.update(optimizer_outcome(prob, maxiter))
    return row


FIGURES = ("touching", "cosine", "relative_error", "growth_swapped", "growth_exact")
def one_step_error(contact: str = "none", collision: str = DEFAULT_COLLISION,
                   stiffness: float = 4.0, dt: float = 1 / 60, amplitude: float = 1.0,
                   speed: float = 1.0, damping: float = 1.0, rows: int = 5,
                   seed: int = 0) -> dict:
    """The paper's claim itself: one swapped backward step against the exact one, from the
    state the sheet reaches after 1/6 s under random forces of ``amplitude`` m/s^2 rms (at
    1/60), stepping ``dt`` from there, for a random cotangent ``(a_x, a_v)`` with
    ``|dt a_x| = |a_v|``: ``local_error = |swapped - exact| / |a|`` in the norm
    ``|(dt a_x, a_v)|``.  O(dt^3) if the paper's bound holds."""
    model, x0 = sheet_model(contact, stiffness=stiffness, collision=collision, rows=rows,
                            speed=speed, damping=damping)
    integrator, rng = LinearizedBackwardEuler("direct"), np.random.default_rng(seed)
    forces = amplitude * rng.standard_normal((10, model.n, 3)) * model.masses[:, None]
    start = simulate(integrator, model, x0, np.zeros_like(x0), forces, REFERENCE_DT)
    first = frame_at(10 * REFERENCE_DT, dt, "one_step_error: 1/6 s")
    work, state, records = integrator.init(model), start.state(10), [None] * first
    states = [state]
    for n in (first, first + 1):  # the step, and the next one (the swapped step's matrix)
        state, record = integrator.step(model, state, np.zeros_like(x0), n, dt, work)
        states.append(state)
        records.append(record)
    free = model.free_mask().reshape(x0.shape)
    a = State(free * rng.standard_normal(x0.shape) / dt, free * rng.standard_normal(x0.shape))
    norm = lambda b: np.sqrt(dt * dt * np.vdot(b.x, b.x) + np.vdot(b.v, b.v))  # noqa: E731
    out = []
    for backward_step in (integrator.step_vjp, integrator.swapped_step_vjp):
        work = integrator.init(model)
        work.records = records
        out.append(backward_step(model, states[0], states[1], records[first], first, dt, a,
                                 work)[0])
    error = State(out[1].x - out[0].x, out[1].v - out[0].v)
    return {"omega_dt": float(dt * np.sqrt(model.params.stretch / model.masses.mean())),
            "local_error": float(norm(error) / norm(a))}


def touching(prob, x) -> float:
    """The fraction of frames ``x`` in which a particle is within a body's contact layer or
    two particles within the self-contact layer."""
    model = prob.model
    if model.self_contact is not None:
        return float(np.mean([model.interactions(frame)[-1][0].size > 0 for frame in x]))
    if not model.colliders:
        return 0.0
    return float(np.mean([any(signed_distances(b, frame, n * prob.dt).min()
                              < b.contact.thickness for b in model.colliders)
                          for n, frame in enumerate(x)]))


def optimizer_outcome(prob, maxiter: int) -> dict:
    """L-BFGS-B from rest with the exact and the swapped route (``maxiter`` each): each
    route's best objective (NaN when the search cannot start: its gradient refused there,
    ``failed_ROUTE`` says why), the evaluations it had refused, and whether the swapped one
    ``reaches`` within 10 % of the exact one (None when the exact one cannot start)."""
    from ..optimize import solve

    out = {"start_objective": prob.objective(prob.initial_controls())}
    for route in (Adjoint.name, Swapped.name):
        out[f"failed_{route}"] = ""
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", GradientRouteWarning)
                result = solve(prob, gradient=route, maxiter=maxiter, quiet=True)
            out[f"objective_{route}"] = result.fun
            out[f"refused_{route}"] = result.stages[0].get("gradient_refused", 0)
        except SimulationError as err:  # its gradient refused at the start (GradientError)
            out[f"objective_{route}"], out[f"refused_{route}"] = np.nan, 1
            out[f"failed_{route}"] = " ".join(str(err).split())[:200]
    exact, swapped = out["objective_adjoint"], out["objective_swapped"]
    out["reaches"] = None if not np.isfinite(exact) else bool(swapped <= REACH * exact)
    return out


DEFAULTS = {"contact": "none", "collision": DEFAULT_COLLISION, "stiffness": 4.0, "dt": 1 / 60,
            "amplitude": 1.0, "horizon": 1 / 3, "speed": 1.0, "damping": 1.0, "rows": 5,
            "solve": False, "maxiter": 40}  # (and measure="step" for the one-step slice)
CASES = (("none", "guarded"), ("ground", "guarded"), ("ground", "penalty"),
         ("sphere", "guarded"), ("sphere", "penalty"), ("capsule", "guarded"),
         ("capsule", "penalty"), ("self", "guarded"))
CURVED = tuple(c for c in CASES if c[0] in ("sphere", "capsule"))


def map_points(quick: bool | None = None) -> dict[str, list[dict]]:
    """The map's slices, each a list of points (every keyword of
    :func:`swap_validity_point` given):

    * ``stiffness``: each contact kind, guarded and penalty, dt sqrt(k/m) from 0.5 to 10 at
      dt 1/60, with the optimizer comparison;
    * ``dt``: the same physical sheets (stiffness 4 at 1/60) at dt 1/30 ... 1/240;
    * ``amplitude``: the random forces' rms, 0.3 to 10 m/s^2;
    * ``speed``: the sphere's and capsule's sliding speed, 0.25 to 4 m/s;
    * ``horizon``: 1/3 to 2 s at stiffness 7 (the cape's contact);
    * ``damping``: the contact damping on curved bodies, 0.01 to 1 of the cape's, at
      stiffness 7 over 1 s;
    * ``step``: one backward step (:func:`one_step_error`) at dt 1/60 ... 1/960 for the
      sheets of stiffness 1 and 4 at 1/60: the paper's O(dt^3) itself.

    ``quick``: two cases and two values per slice on a 4 x 4 sheet (the notebook test)."""
    quick = quick_mode() if quick is None else quick
    cases = (("none", "guarded"), ("capsule", "penalty")) if quick else CASES
    curved = (("capsule", "penalty"),) if quick else CURVED
    base = {**DEFAULTS, "rows": 4 if quick else 5, "maxiter": 10 if quick else 40}

    def slice_(which, key, values, **fixed):
        return [{**base, "contact": c, "collision": k, **fixed, key: v}
                for c, k in which for v in values]

    pick = (lambda full, short: short) if quick else (lambda full, short: full)  # noqa: E731
    return {
        "stiffness": slice_(cases, "stiffness", pick([0.5, 1.0, 2.0, 4.0, 7.0, 10.0],
                                                     [1.0, 7.0]), solve=True),
        "dt": slice_(cases, "dt", pick([1 / 30, 1 / 60, 1 / 120, 1 / 240], [1 / 30, 1 / 60])),
        "amplitude": slice_(cases, "amplitude", pick([0.3, 1.0, 3.0, 10.0], [0.3, 3.0])),
        "speed": slice_(curved, "speed", pick([0.25, 0.5, 1.0, 2.0, 4.0], [0.5, 2.0])),
        "horizon": slice_(cases, "horizon", pick([1 / 3, 2 / 3, 1.0, 2.0], [1 / 3, 2 / 3]),
                          stiffness=7.0),
        "damping": slice_(curved, "damping", pick([0.01, 0.1, 1.0], [0.01, 1.0]),
                          stiffness=7.0, horizon=1.0),
        "step": [p for w in pick([1.0, 4.0], [1.0])
                 for p in slice_(cases, "dt", pick([1 / 60, 1 / 120, 1 / 240, 1 / 480, 1 / 960],
                                                   [1 / 60, 1 / 240]),
                                 stiffness=w, measure="step")],
    }


def swap_validity(quick: bool | None = None) -> dict:
    """The map: :func:`map_points` run in this process (on the sweep runner:
    :func:`~.sweeps.swap_validity_map`), each slice a list of rows (the point's keywords
    and figures), and ``order``: the relative error's fitted order in dt per contact case."""
    return assembled(_run_here(map_points(quick)))


def assembled(study: dict) -> dict:
    """The map's slices ``study`` (name -> rows) with each contact case's fitted orders in
    dt added (``order``, ``step_order``)."""
    cases = dict.fromkeys((r["contact"], r["collision"]) for r in study["dt"])
    study["order"] = {f"{c} {k}": dt_order([r for r in study["dt"]
                                            if (r["contact"], r["collision"]) == (c, k)])
                      for c, k in cases}
    study["step_order"] = {
        f"{c} {k} {w:g}": dt_order([r for r in study["step"] if r["stiffness"] == w
                                    and (r["contact"], r["collision"]) == (c, k)][-3:],
                                   "local_error")
        for c, k in cases for w in dict.fromkeys(r["stiffness"] for r in study["step"])}
    return study


def point_key(values: dict) -> tuple:
    """A point's identity: its keywords' values, in :data:`DEFAULTS`' order, and what it
    measures."""
    return tuple(round(values[k], 12) if isinstance(values[k], float) else values[k]
                 for k in DEFAULTS) + (values.get("measure", "horizon"),)


def _run_here(slices: dict) -> dict:
    """Every slice's rows computed in this process, each distinct point once."""
    done = {}
    for point in (p for points in slices.values() for p in points):
        if point_key(point) not in done:
            done[point_key(point)] = {**point, **swap_validity_point(**point)}
    return {name: [done[point_key(p)] for p in points] for name, points in slices.items()}


def dt_order(rows, figure: str = "relative_error") -> float:
    """``figure``'s fitted order in dt over ``rows`` (NaN for fewer than two finite, positive
    values)."""
    rows = [r for r in rows if r.get(figure, np.nan) > 0 and np.isfinite(r[figure])]
    if len(rows) < 2:
        return float("nan")
    return fitted_order([r["dt"] for r in rows], [r[figure] for r in rows])


SLICES = {"stiffness": ("stiffness", "by stiffness dt sqrt(k/m), dt 1/60, 1/3 s, with L-BFGS-B "
                        "from rest (same iterations)"),
          "dt": ("dt", "by dt, the same sheets (stiffness 4 at 1/60), 1/3 s"),
          "amplitude": ("amplitude", "by the random forces' rms (m/s^2), stiffness 4"),
          "speed": ("speed", "by the body's sliding speed (m/s), stiffness 4"),
          "horizon": ("horizon", "by horizon (s), stiffness 7"),
          "damping": ("damping", "by contact damping (x the cape's), stiffness 7, 1 s")}


def format_swap_validity(study: dict) -> str:
    """The map's tables, one per slice, the fitted orders in dt and :func:`reading`."""
    lines = ["Where the swapped adjoint suffices: against the exact adjoint on a hanging "
             "sheet (1 kg, 1 m), random forces 1 m/s^2 rms"]
    for name, (key, title) in SLICES.items():
        if study.get(name):
            lines += [f"{title}:", *_table(study[name], key, optimizer=name == "stiffness")]
    lines.append("order in dt of the relative error over 1/3 s (the paper's O(dt^3) per step "
                 "would give 2):")
    lines += [f"  {case:18s} {order:6.2f}" for case, order in study["order"].items()]
    if study.get("step"):
        lines += ["one backward step, swapped vs exact, relative error (the paper: O(dt^3)):",
                  *_step_table(study["step"]),
                  "  fitted order over the three finest dt (3 if the paper's bound holds):"]
        lines += [f"  {case:22s} {order:6.2f}" for case, order in study["step_order"].items()]
    return "\n".join(lines + ["reading:"] + [f"  {s}" for s in reading(study)])


def _table(rows, key: str, optimizer: bool) -> list[str]:
    head = (f"  {'contact':8s} {'collision':9s} {key:>9s} {'w dt':>5s} {'touch':>5s} "
            f"{'cosine':>7s} {'rel.err':>8s} {'growth sw':>9s} {'exact':>6s}")
    if optimizer:
        head += f" {'f exact':>8s} {'f swap':>8s} reaches"
    out = [head]
    for r in rows:
        start = f"  {r['contact']:8s} {_collision(r):9s} {_value(r[key], key):>9s} "
        if not np.isfinite(r.get("cosine", np.nan)):
            out.append(start + f"failed: {r.get('reason', '?')[:60]}")
            continue
        line = (start + f"{r['omega_dt']:5.2g} {r['touching']:5.2f} {r['cosine']:7.3f} "
                f"{r['relative_error']:8.2g} {r['growth_swapped']:9.2g} "
                f"{r['growth_exact']:6.2g}")
        if optimizer and "reaches" in r:
            line += (f" {r['objective_adjoint']:8.3g} {r['objective_swapped']:8.3g} "
                     f"{ {True: 'yes', False: 'no', None: 'n/a'}[r['reaches']]}")
        out.append(line)
    return out


def _step_table(rows) -> list[str]:
    """One line per contact case and stiffness: the one-step error at each dt."""
    dts = sorted({r["dt"] for r in rows}, reverse=True)
    out = [f"  {'contact':8s} {'collision':9s} {'stiffness':>9s} "
           + "".join(f"{_value(dt, 'dt'):>9s}" for dt in dts)]
    for case in dict.fromkeys((r["contact"], _collision(r), r["stiffness"]) for r in rows):
        errors = {r["dt"]: r.get("local_error", np.nan) for r in rows
                  if (r["contact"], _collision(r), r["stiffness"]) == case}
        out.append(f"  {case[0]:8s} {case[1]:9s} {case[2]:9g} "
                   + "".join(f"{errors.get(dt, np.nan):9.2g}" for dt in dts))
    return out


def _collision(row) -> str:
    return row["collision"] if row["contact"] in ("ground", "sphere", "capsule") else "-"


def _value(value, key: str) -> str:
    fraction = Fraction(value).limit_denominator(1000)
    if key in ("dt", "horizon") and fraction.denominator > 1 and float(fraction) == value:
        return str(fraction)
    return f"{value:g}"


BANDS = ((0, 2), (4, 4), (7, 10))  # dt sqrt(k/m): soft, the default cloth's, stiff


def reading(study: dict) -> list[str]:
    """The map in sentences, per contact case: the swapped gradient's cosine in each band of
    stiffness, how often L-BFGS-B with it reached the exact route's objective within 10 %,
    its cosine over the longest horizon, its largest backward growth, and the one-step
    error's order in dt (the paper's O(dt^3) holds where it is about 3)."""
    out = []
    for case in dict.fromkeys((r["contact"], r["collision"]) for r in study.get("stiffness", [])):
        mine = lambda key: [r for r in study.get(key, [])  # noqa: E731
                            if (r["contact"], r["collision"]) == case]
        rows = mine("stiffness")
        bands = "; ".join(f"{_span(rows, low, high)} at {low:g}-{high:g}" if low < high else
                          f"{_span(rows, low, high)} at {low:g}" for low, high in BANDS)
        judged = [r for r in rows if r.get("reaches") is not None]
        long = max(mine("horizon"), key=lambda r: r["horizon"], default=None)
        grown = [r for k in ("stiffness", "horizon", "damping", "speed", "amplitude")
                 for r in mine(k)]
        worst, exact = (max((r[k] for r in grown if np.isfinite(r.get(k, np.nan))),
                            default=np.nan) for k in ("growth_swapped", "growth_exact"))
        steps = {k.rsplit(" ", 1)[1]: v for k, v in study.get("step_order", {}).items()
                 if k.rsplit(" ", 1)[0] == f"{case[0]} {case[1]}"}
        label = case[0] if case[0] in ("none", "self") else f"{case[0]} ({case[1]})"
        out.append(
            f"{label}: cosine {bands} (dt sqrt(k/m)); L-BFGS-B within 10 % of the exact "
            f"route at {sum(bool(r['reaches']) for r in judged)} of {len(judged)} stiffnesses"
            + (f"; over {_value(long['horizon'], 'horizon')} s cosine {long['cosine']:.2f}"
               if long else "")
            + f"; backward growth up to {worst:.2g} (exact: {exact:.2g})"
            + ("; one step's error order in dt " + ", ".join(
                f"{order:.1f} at stiffness {w}" for w, order in steps.items()) if steps else ""))
    return out


def _span(rows, low: float, high: float) -> str:
    """The range of cosines of ``rows`` with stiffness in [low, high]."""
    cosines = [r["cosine"] for r in rows if low <= r["stiffness"] <= high
               and np.isfinite(r.get("cosine", np.nan))]
    if not cosines:
        return "-"
    return (f"{min(cosines):.2f}" if len(cosines) == 1 or min(cosines) == max(cosines) else
            f"{min(cosines):.2f}-{max(cosines):.2f}")
