"""Where a step's time goes: the forward passes of the contact cost cases split into assembly
(forces, the step matrix and its projection, right-hand sides and products), kernels (the
compiled per-interaction CasADi kernels, wherever called), factorisation (CHOLMOD's analysis
and numeric factorisation), solves, contact queries (the families' decisions: the hold's
candidates and revisions, springs taken taut, a mesh's closest points) and the rest; then
the solves per step, and one numeric refactorisation of the last step's own matrix.

Each category is timed exclusively (a call inside another category's counts for the inner
one), CPU time (``time.process_time``), one BLAS thread, the median of ``--repeat`` passes
of each case after one warm-up pass.  It patches the library's classes by name, so it runs
on any revision since the contact wing (``PYTHONPATH=/other/checkout`` measures another).

    .venv/bin/python benchmarks/step_time.py [--cases drop free arch penalty mesh sphere]
        [--repeat 3]
"""
import os

for _name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_name, "1")

import argparse  # noqa: E402
import statistics  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

sys.path.insert(0, str(Path(__file__).parent))

from contact import mesh_cost_problem, perturbed_arch, sphere_drop  # noqa: E402

CATEGORIES = ("assembly", "kernels", "factorisation", "solves", "contact queries")


def targets():
    """``{category: [(owner, attribute), ...]}``: what each category times."""
    from casadi_keyframe import kernels
    from casadi_keyframe.integrators import linearized_backward_euler as lbe
    from casadi_keyframe.linear import cholesky, system
    from casadi_keyframe.models import blocks, families
    out = {"assembly": [(lbe.LinearizedBackwardEuler, "step_system"),
                        (families.FamilyModel, "forces"), (blocks.Blocks, "matvec"),
                        (lbe, "held_rhs")],
           "kernels": [(kernels.MappedKernel, "__call__")],
           "factorisation": [(cholesky.CholeskyPlan, "factor")],
           "solves": [(system.Factored, "solve"), (system.Factored, "solve_transpose")],
           "contact queries": [(families.FamilyModel, name) for name in
                               ("step_decisions", "revised_decisions", "solved_decisions",
                                "carried_decisions")]}
    bordered = getattr(cholesky, "BorderedFactor", None)
    if bordered is not None:  # a revision that only releases: solved on the kept factor
        out["factorisation"].append((cholesky.CholeskyPlan, "bordered"))
    return out


class Clock:
    """Exclusive CPU time per category, by wrapping each target while it is installed."""

    def __init__(self):
        self.spent = dict.fromkeys(CATEGORIES, 0.0)
        self.stack = []
        self.saved = []

    def wrap(self, category, function):
        clock = self

        def timed(*args, **kwargs):
            start = time.process_time()
            clock.stack.append(0.0)
            try:
                return function(*args, **kwargs)
            finally:
                inner = clock.stack.pop()
                elapsed = time.process_time() - start
                clock.spent[category] += elapsed - inner
                if clock.stack:
                    clock.stack[-1] += elapsed
        return timed

    def __enter__(self):
        for category, items in targets().items():
            for owner, name in items:
                original = owner.__dict__.get(name) if isinstance(owner, type) else getattr(
                    owner, name)
                if original is None:
                    original = getattr(owner, name)
                self.saved.append((owner, name, owner.__dict__.get(name)
                                   if isinstance(owner, type) else original))
                setattr(owner, name, self.wrap(category, original))
        return self

    def __exit__(self, *exc):
        for owner, name, original in reversed(self.saved):
            if original is None:
                delattr(owner, name)
            else:
                setattr(owner, name, original)
        self.saved.clear()


def refactorisation(prob, u, repeat: int) -> float:
    """CPU seconds of one CHOLMOD numeric factorisation of the last step's own matrix (its
    analysis reused), the median of ``repeat``."""
    from casadi_keyframe.linear import SparseCholesky, System
    integrator = prob.integrator
    traj = prob.simulate(u)
    n = prob.steps - 1
    record = traj.record(n)
    work = integrator.init(prob.model)
    system = integrator.step_system(prob.model, traj.x[n], traj.v[n], n * prob.dt, prob.dt,
                                    work, interactions=record.decisions, held=record.held)
    block = system.matrix.free_block
    plan, key = SparseCholesky().init(block.shape[0] * [True]), object()
    own = System(block, block.dot, block.dot, key)
    plan.factor(own)
    times = []
    for _ in range(repeat):
        t = time.process_time()
        plan.factor(own)
        times.append(time.process_time() - t)
    return statistics.median(times)


def breakdown(prob, u, repeat: int) -> dict:
    """Median CPU seconds per step of each category and in all, over ``repeat`` passes."""
    prob.simulate(u, records=False)  # warm-up: kernels compiled, analyses made
    rounds = []
    for _ in range(repeat):
        with Clock() as clock:
            t = time.process_time()
            prob.simulate(u, records=False)
            total = time.process_time() - t
        rounds.append({**clock.spent, "total": total})
    out = {k: statistics.median(r[k] for r in rounds) / prob.steps for k in rounds[0]}
    out["rest"] = out["total"] - sum(out[k] for k in CATEGORIES)
    return out


CASES = {"drop": ("50x50 sheet at 8 m/s onto a sphere, guarded", lambda: sphere_drop(True)),
         "free": ("the same sheet falling freely", lambda: sphere_drop(False)),
         "arch": ("cloth_arch 50x50x100 perturbed, guarded", lambda: perturbed_arch("guarded")),
         "penalty": ("cloth_arch 50x50x100 perturbed, penalty springs",
                     lambda: perturbed_arch("penalty")),
         "mesh": ("25x25 sheet at 8 m/s onto an icosphere mesh", lambda: mesh_cost_problem(True)),
         "sphere": ("25x25 sheet at 8 m/s onto the analytic sphere",
                    lambda: mesh_cost_problem(False))}


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", nargs="+", default=list(CASES), choices=list(CASES))
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    print(f"ms per step (CPU, one BLAS thread, median of {args.repeat}); each category "
          "exclusive of the others")
    head = "".join(f"{c:>16s}" for c in CATEGORIES + ("rest", "total"))
    print(f"{'case':8s}{head}{'solves/step':>13s}{'refactor ms':>13s}{'step/refactor':>15s}")
    for name in args.cases:
        prob, u = CASES[name][1]()
        b = breakdown(prob, u, args.repeat)
        traj = prob.simulate(u)
        solves = sum(r.solves for r in traj.records) / prob.steps
        refactor = refactorisation(prob, u, args.repeat)
        cells = "".join(f"{1e3 * b[c]:16.2f}" for c in CATEGORIES + ("rest", "total"))
        print(f"{name:8s}{cells}{solves:13.2f}{1e3 * refactor:13.2f}"
              f"{b['total'] / refactor:15.2f}", flush=True)
    print("cases: " + "; ".join(f"{k}: {v[0]}" for k, v in CASES.items() if k in args.cases))


if __name__ == "__main__":
    main()
