"""The search in positions (``method="transcription"``): its inverse step against the
simulation, its Jacobian against central differences, its goal constraints against the
keyframes' misses, its replay against the plan, the method end to end, and the problems it
refuses."""
import numpy as np
import pytest

import casadi_keyframe as ck
from casadi_keyframe import ControlProblem, Smoothness, StateKeyframe
from casadi_keyframe.controls import InitialVelocity, StepForces
from casadi_keyframe.integrators import LinearizedBackwardEuler
from casadi_keyframe.models import ClothModel
from casadi_keyframe.optimize.positions import Transcription, TranscriptionError
from casadi_keyframe.optimize.positions.goal import goal_constraints
from casadi_keyframe.optimize.positions.replay import replay_controls

STEPS = 16


def sheet_problem(controls=None, shift=(0.0, 0.06, 0.0), rows=5):
    """A 5 x 5 sheet pinned at two corners, one keyframe: the passive motion's last frame
    moved by ``shift``, within 1 cm."""
    model = ClothModel.grid(rows, rows, pinned=[0, rows - 1])
    x0 = model.rest_positions
    base = ControlProblem(model=model, integrator=LinearizedBackwardEuler("direct"), x0=x0,
                          v0=np.zeros_like(x0), steps=STEPS, dt=1 / 30,
                          controls=StepForces(), objective=StateKeyframe(STEPS, x=x0),
                          name="sheet")
    target = base.simulate(None, records=False).x[STEPS] + np.asarray(shift)
    target[model.pinned] = x0[model.pinned]
    return ControlProblem(model=model, integrator=base.integrator, x0=x0,
                          v0=np.zeros_like(x0), steps=STEPS, dt=1 / 30,
                          controls=controls or StepForces(),
                          objective=StateKeyframe(STEPS, x=target, position_weight=100.0,
                                                  tolerance=0.01) + Smoothness(1e-4),
                          name="sheet")


def test_the_inverse_step_gives_back_the_forces_that_made_a_run():
    prob = sheet_problem()
    u = 0.01 * np.random.default_rng(0).standard_normal(prob.size)
    tr = Transcription(prob)
    z = tr.unknowns(prob.simulate(u, records=False).x)
    free = np.repeat(prob.model.free_mask().reshape(-1, 3).all(1), 1)
    back = tr.controls(z).reshape(STEPS, -1, 3)[:, free]
    assert np.allclose(back, u.reshape(STEPS, -1, 3)[:, free], rtol=0, atol=1e-12)


def test_the_control_jacobian_is_the_derivative_of_the_forces():
    prob = sheet_problem()
    tr = Transcription(prob)
    rng = np.random.default_rng(1)
    x = prob.simulate(0.01 * rng.standard_normal(prob.size), records=False).x
    x[1:] = 1.15 * x[1:] + 0.001 * rng.standard_normal(x[1:].shape)  # every spring taut
    z = tr.unknowns(x)
    d = rng.standard_normal(z.size)
    J = tr.control_jacobian(z) @ d
    quotients = [(tr.controls(z + h * d) - tr.controls(z - h * d)) / (2 * h)
                 for h in (1e-5, 1e-6, 1e-7)]
    for q in quotients:  # stable over the three steps: the forces are smooth here
        assert np.linalg.norm(q - J) <= 1e-6 * np.linalg.norm(J)


def test_a_goal_constraint_is_the_keyframes_squared_miss_against_its_bound():
    prob = sheet_problem()
    tr = Transcription(prob)
    (c,) = goal_constraints(tr, margin=0.5)
    traj = prob.simulate(None, records=False)
    z = tr.unknowns(traj.x)
    miss = prob.objective_terms.state_terms[0].miss(traj)["rms_position_error"]
    assert c.miss(z) == pytest.approx(miss, rel=1e-12)
    assert c.value(z) == pytest.approx(miss ** 2 - (0.5 * 0.01) ** 2, rel=1e-10)
    g = c.gradient(z)
    d = np.random.default_rng(2).standard_normal(z.size)
    h = 1e-6
    assert (c.value(z + h * d) - c.value(z - h * d)) / (2 * h) == pytest.approx(g @ d, rel=1e-6)


def test_the_replay_lands_on_the_plan_at_every_frame():
    prob = sheet_problem()
    plan = prob.simulate(None, records=False).x
    plan[1:] += np.linspace(0, 1, STEPS)[:, None, None] * [0.0, 0.05, 0.0]
    plan[:, prob.model.pinned] = prob.x0[prob.model.pinned]
    replay = replay_controls(prob, plan)
    assert replay.deviation < 1e-10
    run = prob.simulate(replay.u, records=False)
    assert np.max(np.abs(run.x - plan)) < 1e-10


def test_the_transcription_meets_the_goal_and_lowers_the_effort_of_its_start():
    prob = sheet_problem()
    result = ck.solve(prob, method="transcription", maxiter=25,
                      options={"start": "blend"}, quiet=True)
    tr = Transcription(prob)
    from casadi_keyframe.optimize.positions.method import start_positions
    blend = tr.controls(tr.unknowns(start_positions(prob, "blend", None)))
    assert result.breakdown["misses"][0]["rms_position_error"] <= 0.01
    assert prob.control_cost(result.x)[0] < 0.5 * prob.control_cost(blend)[0]
    assert result.method == "transcription"
    run = prob.simulate(result.x, records=False)
    assert np.allclose(run.x, result.trajectory.x, rtol=0, atol=1e-12)


def test_points_that_meet_the_goal_are_ranked_by_their_control_cost():
    """A start on the keyframe (a kinematic blend, replayed) meets the goal at a high
    effort and a low objective: the transcription's result is its least effort, kept even
    where its objective (the miss at the tolerance's margin) is the higher."""
    from casadi_keyframe.optimize.positions.method import start_positions
    prob = sheet_problem()
    start = replay_controls(prob, start_positions(prob, "blend", None)).u
    result = ck.solve(prob, method="transcription", maxiter=25, u0=start, quiet=True)
    assert result.breakdown["misses"][0]["rms_position_error"] <= 0.01
    assert prob.control_cost(result.x)[0] < 0.5 * prob.control_cost(start)[0]
    assert result.fun > prob.objective(start)  # by the objective alone the start would win


def test_controls_that_are_not_forces_on_every_free_particle_are_refused_by_name():
    prob = sheet_problem(controls=InitialVelocity())
    with pytest.raises(TranscriptionError, match="per-step forces on every free particle"):
        Transcription(prob)
    some = sheet_problem(controls=StepForces(agents=[5, 6]))
    with pytest.raises(TranscriptionError, match="have none"):
        Transcription(some)


def test_an_unknown_start_is_refused_before_the_search():
    prob = sheet_problem()
    with pytest.raises(ValueError, match="start"):
        ck.solve(prob, method="transcription", options={"start": "somewhere"})


def test_the_command_line_solves_a_sheet_from_rest_and_its_controls_replay(tmp_path):
    """``solve cloth_shapes --method transcription --option start=rest`` converges (exit 0)
    with every keyframe within its tolerance, and the written controls replay the result."""
    import json

    from casadi_keyframe.cli import main

    args = ["cloth_shapes", "--set", "rows=4", "--set", "cols=4", "--set", "steps=60"]
    assert main(["solve", *args, "--method", "transcription", "--option", "start=rest",
                 "--out", str(tmp_path), "--quiet", "--no-animation", "--no-viewer"]) == 0
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["method"] == "transcription"
    prob = ck.load_problem("cloth_shapes", rows=4, cols=4, steps=60)
    u = np.load(tmp_path / "result.npz")["u"]
    assert all(m["rms_position_error"] <= 0.02 for m in prob.breakdown(u)["misses"])


def test_the_spring_correction_never_adds_to_the_springs_excess():
    """Steps far past the linear model (random, up to 30 cm a frame) are corrected for the
    stiff springs: the springs' squared excess over their expected lengths never grows,
    where more springs meet at a particle than it has freedoms."""
    from casadi_keyframe.optimize.positions.restore import LengthRestoration, _excess

    prob = sheet_problem()
    tr = Transcription(prob)
    restore = LengthRestoration(tr)
    z = tr.unknowns(prob.simulate(None, records=False).x)
    rng = np.random.default_rng(4)
    x0 = tr.frames(z)[1:]
    length0, d0 = restore.lengths(x0)
    for scale in (0.01, 0.1, 0.3):
        step = scale * rng.standard_normal(z.size)
        x = tr.frames(z + step)[1:]
        expected = length0 + np.einsum("...a,...a->...", d0 / length0[..., None],
                                       (x - x0)[:, restore.j] - (x - x0)[:, restore.i])
        target = np.maximum(expected, restore.rest)
        fixed = tr.frames(restore(z, z + step))[1:]
        assert _excess(restore.lengths(fixed)[0], target) <= _excess(restore.lengths(x)[0],
                                                                     target)


def test_a_plan_that_tears_the_cloth_is_never_kept():
    """A plan with a spring past the model's blow-up stretch is broken (the simulation
    would refuse it): the search treats it as a rejected trial."""
    from casadi_keyframe.optimize.finish.constraint import control_hessian
    from casadi_keyframe.optimize.positions.sqp import PositionSQP

    prob = sheet_problem()
    tr = Transcription(prob)
    solver = PositionSQP(tr, goal_constraints(tr), control_hessian(prob))
    plan = prob.simulate(None, records=False).x
    assert not solver._broken(tr.unknowns(plan))
    plan[7, 12] += [0.0, 5.0, 0.0]  # one particle 5 m out at one frame
    assert solver._broken(tr.unknowns(plan))


def test_the_strain_penalty_is_the_problems_own_term_with_its_slope():
    """The search's strain penalty is the problem's StrainLimit term on the same motion, and
    its gradient ``Jr^T r`` the slope of central differences (stable over three steps)."""
    from casadi_keyframe.objectives import StrainLimit
    from casadi_keyframe.optimize.positions.strain import StrainPenalty

    model = ClothModel.grid(5, 5, pinned=[0, 4])
    x0 = model.rest_positions
    prob = ControlProblem(model=model, integrator=LinearizedBackwardEuler("direct"), x0=x0,
                          v0=np.zeros_like(x0), steps=STEPS, dt=1 / 30,
                          controls=StepForces(),
                          objective=StateKeyframe(STEPS, x=x0, tolerance=0.01)
                          + StrainLimit(1.01, 1e3), name="strained")
    tr = Transcription(prob)
    traj = prob.simulate(None, records=False)
    z = tr.unknowns(traj.x)
    r, J = StrainPenalty(tr).residuals(z)
    term = prob.objective_terms.trajectory_terms[0]
    assert r.size > 0 and 0.5 * r @ r == pytest.approx(term.value(traj), rel=1e-12)
    d = np.random.default_rng(3).standard_normal(z.size)
    slope = (J.T @ r) @ d
    for h in (1e-5, 1e-6, 1e-7):
        ahead, back = (StrainPenalty(tr).residuals(z + s * h * d, False)[0] for s in (1, -1))
        assert (0.5 * ahead @ ahead - 0.5 * back @ back) / (2 * h) == pytest.approx(slope,
                                                                                  rel=1e-5)


def test_the_factorisations_analysis_is_made_once_for_the_whole_search(monkeypatch):
    """The step's matrix keeps one sparsity pattern across iterations (the strain penalty's
    rows and the products' exact zeros come and go): CHOLMOD's analysis runs once."""
    from casadi_keyframe.objectives import StrainLimit
    from casadi_keyframe.optimize.finish.constraint import control_hessian
    from casadi_keyframe.optimize.positions import sqp

    if sqp.cholmod is None:
        pytest.skip("without cvxopt the step's matrix is factored by SuperLU")
    analyses = []
    symbolic = sqp.cholmod.symbolic
    monkeypatch.setattr(sqp.cholmod, "symbolic",
                        lambda *a, **k: analyses.append(1) or symbolic(*a, **k))
    prob = sheet_problem()
    prob = ControlProblem(model=prob.model, integrator=prob.integrator, x0=prob.x0,
                          v0=prob.v0, steps=STEPS, dt=prob.dt, controls=StepForces(),
                          objective=prob.objective_terms + StrainLimit(1.01, 1e3),
                          name="strained")
    tr = Transcription(prob)
    solver = sqp.PositionSQP(tr, goal_constraints(tr), control_hessian(prob))
    outcome, _ = solver.run(tr.unknowns(prob.simulate(None, records=False).x), maxiter=6,
                            tol=1e-12)
    assert outcome.iterations == 6 and len(analyses) == 1


def test_a_resumed_search_goes_on_from_the_given_controls_whatever_its_start():
    """Controls handed in (``u0=``, as ``--resume`` does) are where the search goes on from,
    not the start the options name: the continue line repeats ``start=rest``."""
    prob = sheet_problem()
    first = ck.solve(prob, method="transcription", maxiter=6, options={"start": "rest"},
                     quiet=True)
    again = ck.solve(prob, method="transcription", maxiter=1, options={"start": "rest"},
                     u0=first.x, quiet=True)
    assert "from the given controls' motion (not start=rest)" in again.message
    assert prob.control_cost(again.x)[0] <= prob.control_cost(first.x)[0]


def test_approaching_the_goal_over_several_steps_finds_a_motion_of_less_effort(monkeypatch):
    """From a sheet held still, a search whose every step may remove the whole violation
    commits to the first motion its linear model finds (the sheet held up and folded late);
    the default share (at most half a violation per step) ends, converged, at less effort."""
    from casadi_keyframe.meshes import check_mesh
    from casadi_keyframe.optimize.finish.constraint import control_hessian
    from casadi_keyframe.optimize.positions import sqp
    from casadi_keyframe.optimize.positions.method import start_positions
    from casadi_keyframe.scenes.mesh_cloths import mesh_keyframe_problem
    from casadi_keyframe.scenes.mesh_targets import fold, hanging_sheet, wave

    v, q = hanging_sheet(5, 5)
    prob = mesh_keyframe_problem(
        cloth=check_mesh(v, q), keyframes=[(40, check_mesh(wave(v), q)),
                                           (80, check_mesh(fold(v), q))],
        steps=None, dt=1 / 60, mass=0.3, pinned=[0, 4], control="forces", colliders=[],
        weight=100.0, alpha=1e-4, align=False, strain_limit=1.2, strain_weight=1e3,
        guess="none", rest_band=0.05)
    tr = Transcription(prob)
    z0 = tr.unknowns(start_positions(prob, "rest", None))

    def search():
        solver = sqp.PositionSQP(tr, goal_constraints(tr), control_hessian(prob))
        outcome, point = solver.run(z0, maxiter=80, tol=1e-3)
        assert outcome.reason == "converged" and np.all(point.c <= solver.held)
        return prob.control_cost(point.u)[0]

    gradual = search()
    monkeypatch.setattr(sqp, "THETA_MAX", 1.0)
    assert gradual < 0.8 * search()


def test_contact_that_holds_particles_on_a_body_is_refused_with_what_to_give_instead():
    """The step's hold is a decision the inverse step cannot write: refused by name (it
    crashed inside CasADi before), with the penalty law or the problem's own solve offered."""
    prob = ck.load_problem("mesh_keyframes", spheres=(0.5, -0.3, -0.6, 0.1), guess="none")
    with pytest.raises(TranscriptionError, match="collision='penalty'"):
        Transcription(prob)


def test_a_heavily_damped_step_moves_every_particle_by_its_share_of_the_miss():
    """The keyframe counts every particle alike, and so does the damping metric: at a
    damping that leaves the model out, the step moves each free particle of the keyframe's
    frame in proportion to its miss, the light corners of a lumped mesh no further (a metric
    weighed by each particle's mass squared threw them past their targets)."""
    from casadi_keyframe.meshes import check_mesh
    from casadi_keyframe.optimize.finish.constraint import control_hessian
    from casadi_keyframe.optimize.positions.method import start_positions
    from casadi_keyframe.optimize.positions.sqp import PositionSQP
    from casadi_keyframe.scenes.mesh_cloths import mesh_keyframe_problem
    from casadi_keyframe.scenes.mesh_targets import fold, hanging_sheet

    v, q = hanging_sheet(5, 5)
    prob = mesh_keyframe_problem(
        cloth=check_mesh(v, q), keyframes=[(20, check_mesh(fold(v), q))], steps=None,
        dt=1 / 60, mass=0.3, pinned=[0, 4], control="forces", colliders=[], weight=100.0,
        alpha=1e-4, align=False, strain_limit=1.2, strain_weight=1e3, guess="none",
        rest_band=0.05)
    masses = prob.model.masses
    assert masses.max() > 3 * masses.min()  # the corners are light
    tr = Transcription(prob)
    solver = PositionSQP(tr, goal_constraints(tr), control_hessian(prob))
    x = solver.point(tr.unknowns(start_positions(prob, "rest", None)))
    step = solver._step(x, np.zeros(len(solver.constraints)), 1e10, 0.5)[0]
    frames = tr.frames(x.z + step) - tr.frames(x.z)
    target = prob.objective_terms.state_terms[0].position_target
    at = tr.frames(x.z)[20]
    missed = np.flatnonzero(tr.free.any(axis=1) & (np.linalg.norm(target - at, axis=1) > 1e-3))
    assert masses[missed].min() == masses[tr.free.any(axis=1)].min()  # a light corner in
    miss = target[missed] - at[missed]
    share = np.einsum("ia,ia->i", frames[20][missed], miss) / np.einsum("ia,ia->i", miss, miss)
    assert share.min() > 0 and share.max() < 1.05 * share.min()
