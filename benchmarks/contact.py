"""Contact that holds, measured: free drops of a sheet onto the ground (flat and tilted 30
degrees), a sphere and a capsule, still and moving into the sheet (rising at 2 m/s, a
capsule swinging up at 3 rad/s), per contact model, impact speed and size; then friction
against Coulomb's analytic answers (a sheet on a 20 degree slope, a sheet thrown along the
ground).

For each case it prints the deepest particle inside the body over all frames (mm), the
largest spring stretch, how many linear solves the steps took (a step is solved again when
it must hold more or take springs taut), and the CPU seconds per forward step and per
gradient step (the exact adjoint of a keyframe objective at zero controls: the forward pass
with records plus the backward pass, divided by the steps), then the costs of each contact
model against the paper's penalty springs ("today's") where both ran, and the issue's
checks.  Mesh bodies: the 25 x 25 sheet at 8 m/s on an icosphere OBJ (radius 0.3 m, 2,562
vertices) against the analytic sphere, still and rising, with the same figures for spheres
a few tenths of a millimetre off (how much the scene itself moves with such a change), and
the cape blend's passive fall onto the walking body as capsules, as a mesh and as a mesh
read from a PC2 file (``--only mesh`` runs only these).  One process, one BLAS thread,
``time.process_time``; the cases run in turn, each model's runs of a case next to each other.

The cost table (``--only cost``) is the contact issues' (39, 41): CPU seconds of a forward
pass (no records), the median of ``--repeat`` rounds, each round running every case's two
problems one after the other so that all see the same load: ``cloth_arch`` at 50 x 50 x 100
from a perturbed point (its guess plus white-noise forces of ``NOISE`` m/s^2 rms per
particle and step, seed 0) under the default contact against the paper's penalty springs,
a 50 x 50 sheet dropped at 8 m/s onto a sphere (0.5 s) against the same sheet falling
freely, and the 25 x 25 sheet at 8 m/s onto the icosphere OBJ against the analytic sphere,
with the linear solves per step each took; then a step of the arch and of the drop against
one CHOLMOD numeric refactorisation of its own (last) matrix, timed in the same rounds; and
the targets (1.3x, 1.5x, 1.3x; 1.5x).  ``benchmarks/step_time.py`` splits a step's time.  ``--only
reuse`` measures whether a step solved again could reuse the factor of its first solve
(:func:`reuse`): how much of the matrix a revision changes, and CG preconditioned by the
earlier factor against factorising again.

    .venv/bin/python benchmarks/contact.py [--sizes 25 50] [--speeds 4 8 12]
        [--models penalty guarded constraint] [--duration 0.5] [--repeat 1]
        [--only drops|friction|cost|mesh|reuse]
"""
import os

for _name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_name, "1")

import argparse  # noqa: E402
import statistics  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
import scipy.sparse.linalg as sla  # noqa: E402

from casadi_keyframe import ControlProblem, Smoothness, StateKeyframe, StepForces  # noqa: E402
from casadi_keyframe.integrators import LinearizedBackwardEuler  # noqa: E402
from casadi_keyframe.linear import SparseCholesky, System  # noqa: E402
from casadi_keyframe.loading import load_problem  # noqa: E402
from casadi_keyframe.models import COLLISIONS, ClothModel, MeshBody, Sphere  # noqa: E402
from casadi_keyframe.scenes.body_meshes import write_body  # noqa: E402
from casadi_keyframe.scenes.drops import (MESH_RADIUS, RISE, drop, drop_model,  # noqa: E402
                                          drop_start, ground_throw, icosphere_file, mesh_drop,
                                          slope_slide)
from casadi_keyframe.state import SimulationError  # noqa: E402

NOISE = 10.0  # m/s^2 rms: the perturbed point of the arch (any search iterate)
IMPACTS = [("ground", 0), ("ground", 30), ("sphere", 0), ("capsule", 0), ("rising sphere", 0),
           ("rising capsule", 0), ("swinging capsule", 0)]


def drop_problem(rows, body, speed, tilt, collision, dt, duration, model=None, solver="auto"):
    """The drop's problem (zero controls); ``model`` replaces the sheet and its body,
    ``solver`` is the integrator's linear solver."""
    model = drop_model(rows, body, collision) if model is None else model
    x0, v0 = drop_start(model, speed, tilt)
    steps = int(round(duration / dt))
    objective = StateKeyframe(steps, x=x0 - [0, 0, 0.2], position_weight=1.0 / model.n)
    return ControlProblem(model=model, integrator=LinearizedBackwardEuler(solver), x0=x0, v0=v0,
                          steps=steps, dt=dt, controls=StepForces(),
                          objective=objective + Smoothness(1e-6), name="drop")


def measure(prob, repeat: int) -> dict:
    """Physical figures and the median CPU seconds per forward and per gradient step."""
    u = prob.initial_controls()
    try:
        traj = prob.simulate(u)  # also compiles the kernels
    except SimulationError as err:
        return {"failed": str(err).split(";")[0]}
    report = prob.model.physical_report(traj.x, traj.dt)
    forward, gradient = [], []
    for _ in range(repeat):
        t = time.process_time()
        prob.simulate(u, records=False)
        forward.append(time.process_time() - t)
        t = time.process_time()
        prob.objective_and_gradient(u, "adjoint")
        gradient.append(time.process_time() - t)
    return {"depth_mm": 1e3 * report["max_penetration"], "stretch": report["max_stretch"],
            "solves": sum(r.solves for r in traj.records), "steps": prob.steps,
            "forward": statistics.median(forward) / prob.steps,
            "gradient": statistics.median(gradient) / prob.steps}


def mesh_bodies():
    """The icosphere drops against the analytic sphere, and the cape on the body as a mesh."""
    print("\n25 x 25 sheet at 8 m/s on an icosphere OBJ (r 0.3 m, 2,562 vertices) against "
          "the analytic Sphere (guarded); inside: deepest particle inside the true sphere;"
          " com: largest distance between the runs' centres of mass at any frame")
    for rising in (False, True):
        case = "rising at 2 m/s" if rising else "still"
        t = time.process_time()
        r = mesh_drop(25, 8.0, rising=rising)
        cpu = time.process_time() - t
        if "failed" in r:
            print(f"  {case}: failed: {r['failed']}")
            continue
        frames = np.linalg.norm(r["mesh"]["com"] - r["sphere"]["com"], axis=1)
        within = int(np.argmax(frames > 0.01)) if (frames > 0.01).any() else len(frames)
        print(f"  {case:16s} mesh inside {1e3 * r['mesh']['inside']:5.2f} mm, stretch "
              f"{r['mesh']['stretch']:.3f} (sphere {1e3 * r['sphere']['inside']:5.2f} mm, "
              f"{r['sphere']['stretch']:.3f}); com {100 * r['com']:.2f} cm, within 1 cm "
              f"to frame {within - 1} of {len(frames) - 1}; both runs {cpu:.1f} s CPU")
        for radius, shift in ((MESH_RADIUS - 3e-4, 0.0), (MESH_RADIUS, 1e-4)):
            print(f"    the sphere's own run against r = {1e3 * radius:.1f} mm moved "
                  f"{1e3 * shift:.1f} mm: com {100 * sphere_spread(rising, radius, shift):.2f} cm")
    print("\ncape_blend --set guess=passive, zero forces, 26 x 16, on the walking body:")
    with tempfile.TemporaryDirectory() as folder:
        for body in ("capsules", "mesh", "file"):
            t = time.process_time()
            if body == "file":
                mesh = load_problem("cape_blend", guess="passive", body="mesh")
                body = str(write_body(Path(folder) / "walker.pc2", mesh.model.colliders[0],
                                      mesh.steps * mesh.dt, mesh.dt))
            prob = load_problem("cape_blend", guess="passive", body=body)
            traj = prob.simulate(prob.initial_controls())
            report = prob.model.physical_report(traj.x, prob.dt)
            print(f"  body={Path(body).name:12s} deepest {1e3 * report['max_penetration']:.2f} mm, "
                  f"stretch {report['max_stretch']:.3f}, {time.process_time() - t:.1f} s CPU")


def sphere_spread(rising, radius, shift):
    """The largest distance between the centres of mass of the sheet dropped on the
    analytic sphere and on one of ``radius`` moved ``shift`` m sideways."""
    centre = np.array([0.5, 0.5, -MESH_RADIUS])
    runs = []
    for r, s in ((MESH_RADIUS, 0.0), (radius, shift)):
        at = centre + [s, 0, 0]  # a still sphere is held on its surface, a moving one not
        path = (lambda t, at=at: at + [0, 0, RISE * t]) if rising else at
        runs.append(drop(25, Sphere(path, r), 8.0)[0].x.mean(axis=1))
    return float(np.linalg.norm(runs[0] - runs[1], axis=1).max())


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[25, 50])
    ap.add_argument("--speeds", type=float, nargs="+", default=[4.0, 8.0, 12.0])
    ap.add_argument("--models", nargs="+", default=list(COLLISIONS), choices=COLLISIONS)
    ap.add_argument("--duration", type=float, default=0.5)
    ap.add_argument("--dt", type=float, default=1 / 60)
    ap.add_argument("--repeat", type=int, default=1)
    ap.add_argument("--only", choices=["drops", "friction", "cost", "mesh", "reuse"])
    args = ap.parse_args()
    if args.only in (None, "drops"):
        drops(args)
    if args.only in (None, "friction"):
        friction(args)
    if args.only in (None, "mesh"):
        mesh_bodies()
    if args.only in (None, "cost"):
        cost(max(args.repeat, 3) if args.only is None else args.repeat)
    if args.only in (None, "reuse"):
        reuse()


def drops(args):
    print(f"Free drops, {args.duration:g} s at dt = {args.dt:.4g} s; CPU ms per step (one BLAS "
          f"thread, process_time, median of {args.repeat}); depth: deepest particle inside the "
          "body; solves: linear solves over the steps")
    print(f"{'case':28s} {'model':10s} {'depth mm':>8s} {'stretch':>7s} {'solves':>7s} "
          f"{'fwd ms':>7s} {'grad ms':>7s}")
    rows, checks = [], []
    for k in args.sizes:
        for body, tilt in IMPACTS:
            for speed in args.speeds:
                case = f"{k}x{k} {body}{' tilted' if tilt else ''} {speed:g} m/s"
                results = {}
                for model in args.models:
                    prob = drop_problem(k, body, speed, tilt, model, args.dt, args.duration)
                    r = results[model] = measure(prob, args.repeat)
                    if "failed" in r:
                        print(f"{case:28s} {model:10s} failed: {r['failed']}", flush=True)
                        continue
                    print(f"{case:28s} {model:10s} {r['depth_mm']:8.1f} {r['stretch']:7.2f} "
                          f"{r['solves']:4d}/{r['steps']:<2d} {1e3 * r['forward']:7.1f} "
                          f"{1e3 * r['gradient']:7.1f}", flush=True)
                    if model != "penalty":
                        checks.append((case, model, r))
                rows.append((k, case, results))
    print("\ncost against the paper's penalty springs (where both ran): forward, gradient")
    for k, case, results in rows:
        base = results.get("penalty", {})
        for model, r in results.items():
            if model == "penalty" or "failed" in r or "failed" in base or not base:
                continue
            print(f"  {case:28s} {model:10s} {r['forward'] / base['forward']:5.2f}x "
                  f"{r['gradient'] / base['gradient']:5.2f}x")
    held = [(c, m, r) for c, m, r in checks if "failed" not in r]
    bad = [(c, m) for c, m, r in held if r["depth_mm"] > 5 or r["stretch"] > 1.3]
    print(f"\nno particle deeper than 5 mm, no spring past 1.3x: "
          f"{len(held) - len(bad)} of {len(checks)} drops with a new contact model"
          + ("" if not bad else "; missed: " + "; ".join(f"{c} ({m})" for c, m in bad)))


def friction(args):
    print("\nfriction against Coulomb (within 10 %):")
    for model in [m for m in args.models if m != "penalty"]:
        for mu in (0.2, 0.5):
            slid, analytic = slope_slide(mu, collision=model)
            print(f"  {model:10s} slope 20 deg, mu {mu}: slid {slid:.3f} m in 1 s, "
                  f"g (sin - mu cos) t^2 / 2 = {analytic:.3f} m")
        travelled, analytic = ground_throw(0.3, 3.0, collision=model)
        print(f"  {model:10s} thrown at 3 m/s, mu 0.3: stopped after {travelled:.3f} m, "
              f"v^2 / (2 mu g) = {analytic:.3f} m")


def perturbed_arch(collision: str):
    """``(problem, controls)``: cloth_arch 50 x 50 x 100 at its guess plus :data:`NOISE`."""
    prob = load_problem("cloth_arch", rows=50, cols=50, steps=100, collision=collision)
    noise = np.random.default_rng(0).standard_normal((prob.steps, prob.model.n, 3))
    return prob, prob.initial_controls() + (NOISE * noise * prob.model.masses[:, None]).ravel()


def sphere_drop(body: bool):
    """``(problem, controls)``: a 50 x 50 sheet at 8 m/s onto a sphere, or falling freely."""
    free = None if body else ClothModel.grid(50, 50, width=1.0, height=1.0, plane="xy",
                                             mass=0.3)
    prob = drop_problem(50, "sphere", 8.0, 0, "guarded", 1 / 60, 0.5, model=free)
    return prob, prob.initial_controls()


def mesh_cost_problem(mesh: bool):
    """``(problem, controls)``: the 25 x 25 sheet at 8 m/s onto the icosphere OBJ (radius
    0.3 m, 2,562 vertices, still), or onto the analytic sphere it approximates (guarded)."""
    centre = np.array([0.5, 0.5, -MESH_RADIUS])
    body = Sphere(centre, MESH_RADIUS)
    if mesh:
        with tempfile.TemporaryDirectory() as folder:
            read = MeshBody.from_file(icosphere_file(folder))
        body = MeshBody(read.vertices + centre, read.faces, source=read.source)
    prob = drop_problem(25, None, 8.0, 0, "guarded", 1 / 60, 0.5,
                        model=drop_model(25, body, "guarded"))
    return prob, prob.initial_controls()


def own_refactorisation(prob, u):
    """A function timing one CHOLMOD numeric factorisation of the matrix of ``prob``'s last
    step (as it stood: held set and springs taken taut), its analysis reused."""
    traj = prob.simulate(u)
    n = prob.steps - 1
    record = traj.record(n)
    integrator = prob.integrator
    system = integrator.step_system(prob.model, traj.x[n], traj.v[n], n * prob.dt, prob.dt,
                                    integrator.init(prob.model), interactions=record.decisions,
                                    held=record.held)
    block = system.matrix.free_block
    plan, key = SparseCholesky().init(np.ones(block.shape[0], bool)), object()
    own = System(block, block.dot, block.dot, key)
    plan.factor(own)  # the analysis

    def once():
        t = time.process_time()
        plan.factor(own)
        return time.process_time() - t
    return once


def cost(repeat: int):
    """The contact issue's cost table (module docstring): each round runs every case's two
    problems one after the other, and one refactorisation of the arch's and the drop's own
    last step matrix, so that all see the same load; medians of ``repeat`` rounds."""
    print(f"\ncost: forward CPU s (one BLAS thread, process_time, median of {repeat} "
          "interleaved rounds); solves: linear solves per step")
    cases = [("cloth_arch 50x50x100, guess + 10 m/s^2 noise", ("guarded", "penalty"),
              perturbed_arch, 1.3),
             ("50x50 sheet at 8 m/s onto a sphere, 0.5 s", ("sphere", "free fall"),
              lambda c: sphere_drop(c == "sphere"), 1.5),
             ("25x25 sheet at 8 m/s onto an icosphere OBJ (2,562 vertices), 0.5 s",
              ("mesh", "analytic sphere"), lambda c: mesh_cost_problem(c == "mesh"), 1.3)]
    runs = {(name, c): build(c) for name, pair, build, _ in cases for c in pair}
    refactor = {c: own_refactorisation(*runs[(cases[k][0], c)])
                for k, c in ((0, "guarded"), (1, "sphere"))}
    solves = {key: sum(r.solves for r in p.simulate(u).records) / p.steps
              for key, (p, u) in runs.items()}
    times = {key: [] for key in list(runs) + list(refactor)}
    for _ in range(repeat):
        for key, (p, u) in runs.items():
            t = time.process_time()
            p.simulate(u, records=False)
            times[key].append(time.process_time() - t)
        for c, once in refactor.items():
            times[c].append(statistics.median(once() for _ in range(5)))
    med = {key: statistics.median(t) for key, t in times.items()}
    for name, (new, base), _, bound in cases:
        a, b = med[(name, new)], med[(name, base)]
        print(f"  {name}: {new} {a:.2f} s ({solves[(name, new)]:.2f} solves/step), {base} "
              f"{b:.2f} s ({solves[(name, base)]:.2f}): {a / b:.2f}x (target <= {bound}x: "
              f"{'met' if a / b <= bound else 'MISSED'})", flush=True)
    for (name, c), k in (((cases[0][0], "guarded"), 0), ((cases[1][0], "sphere"), 1)):
        p, _ = runs[(name, c)]
        step = med[(name, c)] / p.steps
        ratio = step / med[c]
        print(f"  a default-path step of the {c} run {1e3 * step:.1f} ms, one numeric "
              f"refactorisation of its own matrix {1e3 * med[c]:.1f} ms: {ratio:.2f}x "
              f"(target <= 1.5x: {'met' if ratio <= 1.5 else 'MISSED'})", flush=True)


class RecordingCholesky(SparseCholesky):
    """CHOLMOD (the default solver here), keeping the free block of every matrix it
    factorises, in order."""

    def __init__(self):
        super().__init__()
        self.blocks = []

    def init(self, free):
        plan = super().init(free)
        factor, blocks = plan.factor, self.blocks

        def recording(A, keep=False):
            blocks.append(plan.system(A).free_block.copy())
            return factor(A, keep)

        plan.factor = recording
        return plan


def reuse():
    """Whether a revision could reuse its step's factor: for every step of the 50 x 50 sphere
    drop solved again, how many rows of the free block the revision changed (a bound on the
    rank of a CHOLMOD update), and CG on the revised matrix preconditioned by the factor of
    the matrix before the revision (to 1e-10, right-hand side the revised matrix times a
    seeded normal vector) against factorising the revised matrix (its analysis reused)."""
    solver = RecordingCholesky()
    prob = drop_problem(50, "sphere", 8.0, 0, "guarded", 1 / 60, 0.5, solver=solver)
    traj = prob.simulate(prob.initial_controls())
    blocks, size = solver.blocks, solver.blocks[0].shape[0]
    starts = np.cumsum([0] + [r.solves for r in traj.records])
    print(f"\nreuse across revisions, 50x50 sheet at 8 m/s onto a sphere: {len(blocks)} "
          f"factorisations over {prob.steps} steps ({size} unknowns); per revision: rows of "
          "the free block it changed, CG iterations and CPU ms with the factor before the "
          "revision as preconditioner, CPU ms of factorising the revised matrix")
    plan, key = SparseCholesky().init(np.ones(size, bool)), object()
    system = lambda A: System(A, A.dot, A.dot, key)  # noqa: E731 (one pattern, one analysis)
    plan.factor(system(blocks[0])).release()
    rows = []
    for n, (first, end) in enumerate(zip(starts[:-1], starts[1:])):
        for k in range(first + 1, end):
            old, new = blocks[k - 1], blocks[k]
            changed = np.unique((new - old).nonzero()[0]).size
            before = plan.factor(system(old), keep=True)
            rhs = new @ np.random.default_rng(0).standard_normal(size)
            count = [0]
            t = time.process_time()
            _, info = sla.cg(new, rhs, rtol=1e-10, maxiter=2000,
                             M=sla.LinearOperator(new.shape, lambda r: before.solve(
                                 np.asarray(r, float).ravel())[0], dtype=float),
                             callback=lambda _: count.__setitem__(0, count[0] + 1))
            cg = time.process_time() - t
            before.release()
            t = time.process_time()
            plan.factor(system(new))
            refactor = time.process_time() - t
            rows.append((changed, count[0], cg, refactor))
            print(f"  step {n:2d} revision {k - first}: {changed:5d} rows changed, CG "
                  f"{count[0]:4d} iterations{'' if info == 0 else ' (not converged)'} "
                  f"{1e3 * cg:6.1f} ms, factorising {1e3 * refactor:5.1f} ms", flush=True)
    changed, its, cg, refactor = (np.array(c) for c in zip(*rows))
    print(f"  median: {np.median(changed):.0f} rows changed, CG {np.median(its):.0f} iterations "
          f"{1e3 * np.median(cg):.1f} ms against factorising {1e3 * np.median(refactor):.1f} ms")


if __name__ == "__main__":
    main()
