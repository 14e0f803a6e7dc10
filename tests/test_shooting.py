"""Multiple shooting: the merit function's gradient is exact (against CasADi reverse mode
through the unrolled segments, and central differences), consistent nodes are single
shooting, workers give the same numbers, and solve(..., shooting=K) composes with the
stages and reports truthfully."""
import casadi as ca
import numpy as np
import pytest

from casadi_keyframe import (CenterOfMassKeyframe, ControlProblem, Smoothness, StateKeyframe,
                             StepForces, StrainLimit)
from casadi_keyframe.integrators import LinearizedBackwardEuler
from casadi_keyframe.optimize import solve
from casadi_keyframe.optimize.evaluator import Evaluator
from casadi_keyframe.optimize.multipliers import Multipliers
from casadi_keyframe.optimize.shooting import Shooting
from casadi_keyframe.optimize.shooting.merit import ShootingMerit
from casadi_keyframe.optimize.shooting.nodes import initial_nodes
from casadi_keyframe.optimize.shooting.placement import growth_spans, step_growth
from casadi_keyframe.optimize.shooting.segments import boundaries
from casadi_keyframe.optimize.shooting.workers import LocalPool, Serial
from casadi_keyframe.scenes.sheets import hanging_sheet
from casadi_keyframe.state import State

STEPS, DT = 12, 1 / 30


def sheet_problem(rows=3, ground=True, collision="guarded"):
    """A small sheet hanging from its top corners (its hem on the ground, touched as
    ``collision`` says), swung forward to a full keyframe with velocities, a centre keyframe
    halfway and a strain limit."""
    model = hanging_sheet(rows, stretch=50.0, ground=ground, collision=collision)
    x0 = model.rest_positions
    target = x0.copy()
    free = np.setdiff1d(np.arange(model.n), model.pinned)
    target[free] += [0.0, 0.2, 0.05]
    objective = (StateKeyframe(STEPS, x=target, v=np.zeros_like(x0), position_weight=20.0,
                               velocity_weight=0.5)
                 + CenterOfMassKeyframe(5, x=x0.mean(0) + [0, 0.1, 0], position_weight=5.0)
                 + Smoothness(2e-2, temporal=1e-4) + StrainLimit(1.05, 10.0))
    return ControlProblem(model=model, integrator=LinearizedBackwardEuler("direct"), x0=x0,
                          v0=np.zeros_like(x0), steps=STEPS, dt=DT, controls=StepForces(),
                          objective=objective, name="sheet")


def random_point(prob, K, rng):
    """A shooting form with K segments at a random point: controls, nodes off the run of
    those controls, multipliers and weights."""
    u = 0.05 * rng.standard_normal(prob.size)
    ref = prob.simulate(u)
    shooting = Shooting(prob, K, ref)
    nodes = [State(s.x + 0.01 * rng.standard_normal(s.x.shape),
                   s.v + 0.05 * rng.standard_normal(s.v.shape)) for s in shooting.nodes_of(ref)]
    mult = Multipliers({(k, c): 0.5 + k for k in range(K - 1) for c in "xv"})
    for block in mult.lam:
        mult.lam[block] = 0.3 * rng.standard_normal(shooting.nf)
    return shooting, shooting.pack(u, nodes), mult


def casadi_merit(shooting, mult) -> ca.Function:
    """The same merit function built independently: CasADi's unrolled symbolic steps per
    segment, the terms' symbolic forms, the defects in MX; reverse mode gives its gradient."""
    p, (sx, sv) = shooting.problem, shooting.sigma
    n, d = p.model.n, p.model.dim
    Z = ca.MX.sym("z", shooting.size)
    U = Z[:p.size]
    forces, _ = p.controls.symbolic(U)
    step = p.integrator.symbolic_step(p.model)
    free = shooting.free.ravel()  # (n, dim) row-major == dim x n column-major
    select = np.zeros((n * d, shooting.nf))
    select[np.flatnonzero(free), np.arange(shooting.nf)] = 1.0
    offset = shooting.m
    starts = [(ca.DM(p.x0.T), ca.DM(p.v0.T))]
    for ref in shooting.reference:
        y = Z[offset:offset + shooting.nf]
        w = Z[offset + shooting.nf:offset + 2 * shooting.nf]
        offset += 2 * shooting.nf
        x = ca.DM((ref.x * ~shooting.free).ravel()) + ca.mtimes(ca.DM(select), sx * y)
        v = ca.DM((ref.v * ~shooting.free).ravel()) + ca.mtimes(ca.DM(select), sv * w)
        starts.append((ca.reshape(x, d, n), ca.reshape(v, d, n)))
    J, frames = 0, {}
    for k, ((a, b), (X, V)) in enumerate(zip(shooting.spans, starts)):
        for m in range(a, b):
            frames[m] = (X, V)
            E = ca.DM(p.external[m].T) + forces[m]
            X, V = step(X, V, E, p.dt, p.integrator.step_parameters(p.model, m * p.dt, p.dt))
        if k < shooting.K - 1:
            nx, nv = starts[k + 1]
            cx = ca.vec(X - nx)[np.flatnonzero(free).tolist()] / sx
            cv = ca.vec(V - nv)[np.flatnonzero(free).tolist()] / sv
            for c, block in ((cx, (k, "x")), (cv, (k, "v"))):
                J += 0.5 * mult.weights[block] * ca.sumsqr(c + mult.shift(block))
        else:
            frames[b] = (X, V)
    for t in p.objective_terms.state_terms:
        J += t.symbolic(*frames[t.frame])
    for m in range(1, p.steps + 1):
        for t in p.objective_terms.trajectory_terms:
            J += t.symbolic(*frames[m], p.dt, m)
    J += p.control_expression(U)
    return ca.Function("merit", [Z], [J, ca.gradient(J, Z)])


def test_boundaries_cut_the_horizon_into_whole_steps():
    assert boundaries(12, 3) == [(0, 4), (4, 8), (8, 12)]
    assert boundaries(10, 4) == [(0, 2), (2, 5), (5, 8), (8, 10)]
    assert boundaries(5, 1) == [(0, 5)]
    with pytest.raises(ValueError, match="do not fit in 5 steps"):
        boundaries(5, 6)
    with pytest.raises(ValueError, match="whole number >= 1"):
        boundaries(5, 0)


@pytest.mark.parametrize("K", [2, 4])
def test_the_merit_and_its_gradient_match_casadi_and_central_differences(K):
    # CasADi's symbolic step is the paper's penalty step: compared on penalty contact
    prob = sheet_problem(collision="penalty")
    rng = np.random.default_rng(K)
    shooting, z, mult = random_point(prob, K, rng)
    f, g, _ = shooting.evaluate(z, Serial(prob, shooting.spans), mult)
    f_ref, g_ref = (np.asarray(a).ravel() for a in casadi_merit(shooting, mult)(z))
    assert f == pytest.approx(float(f_ref[0]), rel=1e-10)
    assert np.linalg.norm(g - g_ref) <= 1e-8 * np.linalg.norm(g_ref)
    # the default contact (held by the step) against central differences
    prob = sheet_problem()
    shooting, z, mult = random_point(prob, K, rng)
    f, g, _ = shooting.evaluate(z, Serial(prob, shooting.spans), mult)
    runner, h = Serial(prob, shooting.spans), 1e-6
    for _ in range(2):
        d = rng.standard_normal(z.size)
        slope = (shooting.evaluate(z + h * d, runner, mult)[0]
                 - shooting.evaluate(z - h * d, runner, mult)[0]) / (2 * h)
        assert g @ d == pytest.approx(slope, rel=1e-5)


def test_segments_placed_by_growth_share_it_equally():
    assert growth_spans(np.ones(12), 3) == [(0, 4), (4, 8), (8, 12)]  # no growth: equal
    ratios = np.ones(20)
    ratios[:5] = 10.0  # all the growth in the first five steps
    spans = growth_spans(ratios, 3)
    assert spans[0][0] == 0 and spans[-1][1] == 20 and spans[1][0] <= 3 and spans[2][0] <= 5
    assert all(b > a for a, b in spans)
    prob = sheet_problem(ground=False)
    u = 0.05 * np.random.default_rng(0).standard_normal(prob.size)
    growth = step_growth(prob, u)
    assert growth.shape == (STEPS,) and np.all(growth > 0)
    r = solve(prob, "lbfgsb", shooting={"segments": 3, "place": "growth", "rounds": 1},
              maxiter=2, quiet=True, stop="method")
    assert "by growth" in r.stages[0]["message"]


@pytest.mark.parametrize("collision", ["guarded", "penalty"])
def test_the_merit_s_residual_form_is_exact(collision):
    """Half its squared residual is the merit, ``J^T r`` its gradient, ``J`` and ``J^T`` pass
    the dot test and ``J d`` is the residuals' central difference."""
    prob = sheet_problem(collision=collision)
    rng = np.random.default_rng(7)
    shooting, z, mult = random_point(prob, 3, rng)
    runner = Serial(prob, shooting.spans)
    f, g, _ = shooting.evaluate(z, runner, mult)
    merit = ShootingMerit(prob, shooting, runner, mult)
    lin = merit.linearize(z)
    try:
        assert lin.value == pytest.approx(f, rel=1e-12)
        np.testing.assert_allclose(lin.vjp(lin.residual), g, rtol=1e-9, atol=1e-9 * np.abs(
            g).max())
        d, w = rng.standard_normal(z.size), rng.standard_normal(lin.residual.size)
        jd = lin.jvp(d)
        assert jd @ w == pytest.approx(d @ lin.vjp(w), rel=1e-9)
        h = 1e-6
        plus, minus = merit.linearize(z + h * d), merit.linearize(z - h * d)
        difference = (plus.residual - minus.residual) / (2 * h)
        plus.release(), minus.release()
        assert np.linalg.norm(difference - jd) <= 1e-5 * np.linalg.norm(jd)
    finally:
        lin.release()


def test_gauss_newton_runs_multiple_shooting():
    prob = sheet_problem(collision="penalty")
    start = prob.objective(prob.initial_controls())
    r = solve(prob, "gauss-newton", shooting={"segments": 3, "init": "guess", "rounds": 1},
              maxiter=3, quiet=True, stop="method")
    assert r.stages[0]["segments"] == 3 and r.stages[0]["nit"] > 0
    assert r.fun < 0.5 * start


@pytest.mark.parametrize("collision", ["guarded", "penalty"])
def test_one_segment_is_single_shooting_and_consistent_nodes_have_no_defect(collision):
    """Guarded contact carries decisions from step to step (a contact that pulled is let go
    at the next): each segment starts from what the previous one's last step carried, in
    this process and in workers (which sweep from the last sweep's carries and sweep again
    any segment whose carry was wrong)."""
    prob = sheet_problem(collision=collision)
    rng = np.random.default_rng(0)
    u = 0.05 * rng.standard_normal(prob.size)
    ref = prob.simulate(u)
    one = Shooting(prob, 1, ref)
    f, g, _ = one.evaluate(one.pack(u, []), Serial(prob, one.spans), Multipliers({}))
    f1, g1 = prob.objective_and_gradient(u)
    assert f == f1 and np.array_equal(g, g1)
    three = Shooting(prob, 3, ref)
    mult = Multipliers({(k, c): 1.0 for k in range(2) for c in "xv"})
    f3, _, info = three.evaluate(three.pack(u, three.nodes_of(ref)),
                                 Serial(prob, three.spans), mult)
    assert f3 == pytest.approx(f1, rel=1e-12) and three.defect_size(info["defects"]) < 1e-9
    np.testing.assert_allclose(info["trajectory"].x, ref.x, atol=1e-12)
    pool = LocalPool(prob, three.spans, 2)
    try:
        three.carried = [None] * three.K  # a first sweep: every later carry guessed wrong
        fp, _, info = three.evaluate(three.pack(u, three.nodes_of(ref)), pool, mult)
    finally:
        pool.close()
    assert fp == pytest.approx(f3, rel=1e-12)
    np.testing.assert_allclose(info["trajectory"].x, ref.x, atol=1e-12)
    if collision == "guarded":
        assert three.rerun > 0  # the hem on the ground: contacts carried across the nodes


def test_segments_in_worker_processes_give_the_same_numbers():
    prob = sheet_problem()
    shooting, z, mult = random_point(prob, 3, np.random.default_rng(5))
    f, g, _ = shooting.evaluate(z, Serial(prob, shooting.spans), mult)
    pool = LocalPool(prob, shooting.spans, 2)
    try:
        for _ in range(2):  # the workers keep each forward pass for its backward pass
            fp, gp, _ = shooting.evaluate(z, pool, mult)
            assert fp == f and np.array_equal(gp, g)
    finally:
        pool.close()
    assert all(not p.is_alive() for p in pool.processes) and not pool.pipes


def test_nodes_start_passive_on_the_target_or_blended_between():
    prob = sheet_problem()
    ref = prob.simulate()
    shooting = Shooting(prob, 3, ref)
    passive = initial_nodes(prob, shooting, "passive", ref)
    target = initial_nodes(prob, shooting, "target", ref)
    blend = initial_nodes(prob, shooting, "blend", ref)
    key = prob.objective_terms.state_terms[0]
    free = shooting.free
    for (a, _), p, t, b in zip(shooting.spans[1:], passive, target, blend):
        np.testing.assert_allclose(p.x, ref.x[a])
        np.testing.assert_allclose(t.x[free], key.position_target[free])
        np.testing.assert_allclose(t.x[~free], ref.x[a][~free])  # pins stay prescribed
        tau = a / key.frame
        np.testing.assert_allclose(b.x[free], ((1 - tau) * p.x + tau * t.x)[free])
    flock = prob.with_objective(CenterOfMassKeyframe(STEPS, x=[0, 0.2, 0]) + Smoothness(1e-3))
    with pytest.raises(ValueError, match="needs a StateKeyframe with a position target"):
        initial_nodes(flock, Shooting(flock, 3, ref), "blend", ref)


def test_the_defect_jacobian_matches_central_differences_in_this_process_and_in_workers():
    prob = sheet_problem()
    rng = np.random.default_rng(3)
    shooting, z, _ = random_point(prob, 3, rng)
    serial = Serial(prob, shooting.spans)

    def defects(point):
        return shooting.defect_vector(shooting.evaluate(point, serial, None)[2]["defects"])

    shooting.evaluate(z, serial, None)
    jac = shooting.defect_jacobian(serial).toarray()
    h = 1e-6
    for _ in range(3):
        d = rng.standard_normal(z.size)
        slope = (defects(z + h * d) - defects(z - h * d)) / (2 * h)
        np.testing.assert_allclose(jac @ d, slope, rtol=1e-5, atol=1e-7 * np.abs(slope).max())
    pool = LocalPool(prob, shooting.spans, 2)
    try:
        shooting.evaluate(z, pool, None)
        assert np.array_equal(shooting.defect_jacobian(pool).toarray(), jac)
    finally:
        pool.close()


def test_solve_with_shooting_reports_each_part_and_judges_by_the_controls_own_run():
    prob = sheet_problem(ground=False)
    result = solve(prob, maxiter=40, quiet=True, stop="method",
                   shooting={"segments": 3, "init": "blend", "rounds": 2})
    shooting, polish = result.stages
    assert shooting["segments"] == 3 and "multiple shooting, 3 segments" in shooting["message"]
    assert "segments" not in polish and (shooting["stage"], polish["stage"]) == (0, 1)
    assert result.nit == shooting["nit"] + polish["nit"] == len(result.history)
    assert [h["stage"] for h in result.history] == [0] * shooting["nit"] + [1] * polish["nit"]
    assert result.fun == polish["fun"]  # one story: the last stage's objective is the result's
    records = [h for h in result.history if "defect" in h]
    assert len(records) == shooting["nit"] and records[-1]["defect"] < records[0]["defect"]
    # the result is the problem's own: its controls simulated from the start
    assert result.fun == pytest.approx(prob.objective(result.x), rel=1e-12)
    with pytest.raises(ValueError, match="shooting init must be one of"):
        solve(prob, shooting={"segments": 3, "init": "nowhere"})
    with pytest.raises(ValueError, match="unknown option"):
        solve(prob, shooting={"segments": 3, "nodes": "blend"})


def test_the_ipopt_formulation_holds_the_defects_as_constraints_and_reports_its_iterates():
    """IPOPT with the defects as equality constraints (their sparse Jacobian by backward
    sweeps): the defects stay a fraction of the tolerance while the objective falls, and
    the stage ends on IPOPT's last iterate, the one each record described last."""
    prob = sheet_problem(ground=False)
    result = solve(prob, maxiter=15, quiet=True, stop="method",
                   shooting={"segments": 3, "init": "blend", "formulation": "ipopt",
                             "polish": False})
    (stage,) = result.stages
    records = [h for h in result.history if "defect" in h]
    assert "3 segments, 1 rounds" in stage["message"] and "IPOPT" in stage["message"]
    assert len(records) == stage["nit"] == 15 and {h["round"] for h in records} == {0}
    assert records[-1]["objective"] < 0.5 * records[0]["objective"]
    assert stage["defect"] < 0.1 and stage["defect"] == pytest.approx(records[-1]["defect"])
    assert stage["fun"] == pytest.approx(records[-1]["objective"], rel=1e-12)


def test_segments_on_a_dask_cluster_give_the_same_numbers():
    distributed = pytest.importorskip("distributed")
    from casadi_keyframe import load_problem
    from casadi_keyframe.optimize.shooting.dask_pool import DaskPool

    prob = load_problem("cloth_shapes", rows=3, cols=3, steps=12)
    shooting, z, mult = random_point(prob, 3, np.random.default_rng(2))
    f, g, _ = shooting.evaluate(z, Serial(prob, shooting.spans), mult)
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  host="127.0.0.1", dashboard_address=None) as cluster:
        pool = DaskPool(prob, shooting.spans, cluster.scheduler_address, 2)
        try:
            fd, gd, _ = shooting.evaluate(z, pool, mult)
        finally:
            pool.close()
    assert fd == f and np.array_equal(gd, g)
    with pytest.raises(ValueError, match="not built from a problem file"):
        DaskPool(sheet_problem(), shooting.spans, "tcp://127.0.0.1:1", 2)


def test_a_new_round_evaluates_its_own_merit_at_the_point_the_last_one_ended():
    """The multipliers move between rounds, so the memo of the last point is stale: a round
    that started from it with the old merit's value and gradient failed its first line
    search (seen: every other round of the cape's 1 iteration)."""
    prob = sheet_problem()
    shooting, z, mult = random_point(prob, 3, np.random.default_rng(4))
    merit = ShootingMerit(prob, shooting, Serial(prob, shooting.spans), mult)
    ev = Evaluator(prob, None, None, merit=merit, report="best", failed_best=False)
    before = ev(z)[0]
    c = ev.last_info.defects
    mult.update({**{(k, "x"): cx for k, (cx, _) in enumerate(c)},
                 **{(k, "v"): cv for k, (_, cv) in enumerate(c)}})
    ev.reset()
    after = ev(z)[0]
    assert after != before and after == shooting.evaluate(z, Serial(prob, shooting.spans),
                                                          mult)[0]


def test_the_command_line_runs_multiple_shooting_and_refuses_bad_options(tmp_path, capsys):
    import json

    from casadi_keyframe.cli import main

    small = ["solve", "flock_path", "--set", "agents=6", "--set", "steps=20", "--set",
             "tolerance=2", "--quiet", "--no-animation", "--no-viewer"]
    code = main(small + ["--segments", "2", "--shooting", "init=passive,workers=2",
                         "--maxiter", "30", "--out", str(tmp_path)])
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert code in (0, 3) and summary["stages"][0]["segments"] == 2
    assert "multiple shooting, 2 segments" in capsys.readouterr().out
    for bad, message in ((["--shooting", "init=nowhere"], "shooting init must be one of"),
                         (["--shooting", "nodes=blend"], "unknown option"),
                         (["--homotopy", "nothing=3"], "nothing")):
        assert main(small + ["--segments", "2", *bad, "--out", str(tmp_path / "b")]) == 2
        assert message in capsys.readouterr().err
