"""An experiment on why a search stalls on a hanging sheet, and one model change tried against it.

The Choi-Ko law's radial stiffness jumps at a spring's rest length (``k_t`` in tension, the
buckling slope ``24 k_b / L^3`` under compression, 750 times smaller on the 12 x 12 sheet),
and the linearized step takes its matrix at the step's start: a spring whose start-of-step
length crosses its rest length switches the step's matrix, so the simulated motion, and the
objective, jump with the controls.  :class:`RestStiffness` is a family that adds to each
compressed spring within ``band`` (relative) of its rest length the stiffness it lacks,
blended in by a smoothstep: the step's matrix becomes continuous, the force stays the
paper's law (another first-order linearization of the same model); ``band = 0`` is the
paper's step.  The script measures, at the stall of a Gauss-Newton search from zero forces:

* along the gradient, the objective's change against its linear prediction for steps from
  1e-6 to 1e-2 (the linearity radius), and how many springs switch branch at each step;
* the search continued through bands fading to the paper's step (``solve``'s homotopy
  levels), the misses on the paper's model after each.

    python benchmarks/rest_stiffness.py --bands 0.05,0.01,0.002 --maxiter 30
"""
from __future__ import annotations

import argparse
import os
import sys
import time

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import casadi as ca  # noqa: E402
import numpy as np  # noqa: E402

from casadi_keyframe.kernels import interaction_kernels  # noqa: E402
from casadi_keyframe.loading import load_problem  # noqa: E402
from casadi_keyframe.models import ClothModel  # noqa: E402
from casadi_keyframe.models.interaction import PairInteraction  # noqa: E402
from casadi_keyframe.models.springs import BEND, REST_TOLERANCE, sinc_inverse_squared  # noqa: E402
from casadi_keyframe.optimize import solve  # noqa: E402
from casadi_keyframe.optimize.residual.linearization import linearize  # noqa: E402
from casadi_keyframe.problem import ControlProblem  # noqa: E402


def rest_kernels(eps: float, band: float) -> dict:
    """Zero force; stiffness ``b(r) max(k_t - m_c'(r), 0) u u^T`` for ``r < L``, b the
    smoothstep from 0 at ``(1 - band) L`` to 1 at L, ``m_c`` the law's buckling branch."""
    d, dv = ca.SX.sym("d", 3), ca.SX.sym("dv", 3)
    L, k_t, k_b, rs = (ca.SX.sym(n) for n in ("L", "k_t", "k_b", "rs"))
    r = ca.sqrt(ca.dot(d, d) + eps ** 2)
    u = d / r
    slope = ca.substitute(ca.jacobian(-k_b * 4 * sinc_inverse_squared(rs / L) / L ** 2, rs),
                          rs, r)
    s = ca.fmin(ca.fmax((r / L - (1 - band)) / band, 0), 1)
    lack = ca.if_else(r >= L * (1 - REST_TOLERANCE), 0,
                      s * s * (3 - 2 * s) * ca.fmax(k_t - slope, 0))
    name = "rest_stiffness_" + f"{band:g}".replace(".", "p").replace("-", "m")
    return interaction_kernels(name, d, dv, [L, k_t, k_b], ca.SX.zeros(3),
                               lack * ca.mtimes(u, u.T))


class RestStiffness(PairInteraction):
    """The stiffness a compressed spring near rest lacks, over the cloth's springs."""

    name, role = "rest_stiffness", "internal"

    def __init__(self, cloth, band: float):
        super().__init__(rest_kernels(cloth.params.eps, band), cloth.n, cloth.jit)
        s, p = cloth.springs, cloth.params
        k_t = np.choose(s.kind, [p.stretch, p.shear, 0.0]).astype(float)
        k_t = np.where(s.kind == BEND, 24 * p.bend / s.rest ** 3, k_t)
        self.columns = [s.rest[:, None], k_t[:, None], np.full((s.rest.size, 1), p.bend)]
        self.ij = (s.i, s.j)

    def pairs(self, found):
        return self.ij

    def all_pairs(self):
        return self.ij

    def pair_parameters(self, i, j, found=None):
        return self.columns

    def forces(self, x, v, t, found):
        return None


def stiffened(prob, band: float) -> ControlProblem:
    """``prob`` (a cloth without extra families) whose step adds :class:`RestStiffness`."""
    m = prob.model
    cloth = ClothModel(m.rest_positions, m.faces, m.masses, m.springs, m.params, m.pinned,
                       m.jit, colliders=m.colliders, self_contact=m.self_contact,
                       attachments=m.attachments, families=(RestStiffness(m, band),),
                       collision=m.collision)
    return ControlProblem(model=cloth, integrator=prob.integrator, x0=prob.x0, v0=prob.v0,
                          steps=prob.steps, dt=prob.dt, controls=prob.controls.for_steps(
                              prob.steps), objective=prob.objective_terms,
                          external=prob.external, name=prob.name, view=prob.view)


def branches(prob, traj) -> np.ndarray:
    s = prob.model.springs
    return s.stretch(traj.x) >= 1 - REST_TOLERANCE


def linearity(prob, u, label: str) -> None:
    """The objective along the gradient against its linear prediction, and the springs
    that switch branch on the way."""
    lin = linearize(prob, u)
    g = lin.gradient()
    d, f0 = -g / np.linalg.norm(g), lin.value
    before = branches(prob, lin.trajectory)
    lin.release()
    line = []
    for t in (1e-6, 1e-5, 3e-5, 1e-4, 3e-4, 1e-3, 3e-3, 1e-2):
        traj = prob.simulate(u + t * d, records=False)
        f = prob.state_cost(traj, gradient=False)[0] + prob.control_cost(u + t * d)[0]
        flips = int(np.sum(branches(prob, traj) != before))
        line.append(f"{t:.0e}: {(f - f0) / (t * (g @ d)):.2f} ({flips})")
    print(f"  {label}: actual / linear change (springs switched) " + "  ".join(line))


def effort(prob, u) -> str:
    found = prob.effort(u)
    return (f"acc rms {found['rms_acceleration']:.1f} peak {found['peak_acceleration']:.1f} "
            "m/s^2")


def misses(prob, u) -> str:
    b = prob.breakdown(u)
    return (",".join(f"{1e3 * m['rms_position_error']:.1f}" for m in b["misses"])
            + f" mm, stretch {b['physical']['max_stretch']:.3f}")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--bands", default="0.05,0.01,0.002")
    parser.add_argument("--maxiter", type=int, default=30)
    parser.add_argument("--stall-iterations", type=int, default=12)
    args = parser.parse_args(argv)
    paper = load_problem("mesh_keyframes", guess="none")
    bands = [float(b) for b in args.bands.split(",")]
    stall = solve(paper, "gauss-newton", quiet=True, maxiter=args.stall_iterations).x
    print(f"stall of gauss-newton from zero forces: {misses(paper, stall)}")
    linearity(paper, stall, "paper's step")
    for band in bands:
        linearity(stiffened(paper, band), stall, f"band {band:g}")
    t = time.process_time()
    levels = [stiffened(paper, b) for b in bands]
    r = solve(paper, "gauss-newton", quiet=True, maxiter=args.maxiter, homotopy=levels)
    for stage in r.stages:
        print(f"  level {stage['stage']}: {stage['nit']} iterations, {stage['nfev']} "
              f"evaluations, {stage['seconds']:.0f} s: {stage['message'][:90]}")
    print(f"bands {args.bands} then the paper's step, from zero forces: "
          f"{misses(paper, r.x)}, {effort(paper, r.x)}, {time.process_time() - t:.0f} s CPU")
    return 0


if __name__ == "__main__":
    sys.exit(main())
