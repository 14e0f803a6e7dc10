"""Multiple shooting's merit as residuals, ``0.5 |r(z)|^2``, linearized at a point: what a
residual search (the Gauss-Newton trust region, scipy's ``least_squares``) needs of
:class:`~.merit.ShootingMerit`.

``r`` stacks the problem's residuals on the stitched trajectory (keyframe misses, strain
excess, control effort, as :func:`~..residual.linearization.linearize` does) and each defect block's
``sqrt(w_b) (c_b + lambda_b / w_b)`` (:class:`~..multipliers.Multipliers`: its part of the
merit is half its square).  ``J p`` is one tangent pass per segment along its recorded run
(the integrators' exact ``step_jvp``), ``J^T w`` one backward sweep per segment
(:meth:`~.form.Shooting.pull_back`, the merit's own).  The segments run in this process,
on a runner of their own (the evaluator's runner moves with its trial points).
"""
from __future__ import annotations

import numpy as np

from ...simulate import tangent
from ..residual.linearization import Linearization, TermResiduals
from ...integrators.shifted import Shifted
from .workers import Serial


def linearize_shooting(merit, z) -> Linearization:
    """The residual map of ``merit`` (a :class:`~.merit.ShootingMerit` with multipliers) at
    ``z``, as the one :class:`~..residual.linearization.Linearization`: one sweep per
    segment, its records kept (on a runner of its own) for the products until released."""
    if merit.mult is None:
        raise ValueError("a residual search runs multiple shooting's augmented "
                         "Lagrangian (formulation 'lagrangian'), not its IPOPT form")
    s, mult = merit.shooting, merit.mult
    p = s.problem
    z = np.asarray(z, dtype=float)
    u, nodes = s.unpack(z)
    starts, ext = s.starts_and_forces(u, nodes)
    runner = Serial(p, s.spans)
    out = runner.forward({k: (st, e, None) for k, (st, e) in enumerate(zip(starts, ext))})
    frames = [out[k][:2] for k in range(s.K)]
    trajectory = s.stitch(frames)
    terms = TermResiduals(p)
    blocks = [(k, c) for k in range(s.K - 1) for c in ("x", "v")]
    root = np.array([np.sqrt(mult.weights[b]) for b in blocks])
    defects = [c for pair in s.defects(frames, nodes) for c in pair]
    pieces = (terms.pieces(trajectory, u)
              + [r * (c + mult.shift(b)) for r, c, b in zip(root, defects, blocks)])
    ends = np.cumsum([q.size for q in pieces])

    def jvp(dz):
        """``J dz``: one tangent pass per segment from its start's change."""
        du, dnodes = s.unpack_change(np.asarray(dz, dtype=float).ravel())
        offset, forces = p.controls.velocity_offset(du), p.controls.external(du)
        forces = np.zeros_like(p.external) if forces is None else forces
        begins = [(np.zeros_like(p.x0), np.zeros_like(p.v0) if offset is None else offset)]
        begins += [(dx, dv) for dx, dv in dnodes]
        moved = []
        for k, (a, b) in enumerate(s.spans):
            moved.append(tangent(Shifted(p.integrator, a), p.model, runner.runner.kept[k],
                                 *begins[k], forces[a:b]))
        stitched = s.stitch(moved)
        parts = terms.jvp(trajectory, stitched.x, stitched.v, du)
        sx, sv = s.sigma
        for k, (dx, dv) in enumerate(moved[:-1]):
            node_x, node_v = begins[k + 1]
            parts += [root[2 * k] * (dx[-1] - node_x)[s.free] / sx,
                      root[2 * k + 1] * (dv[-1] - node_v)[s.free] / sv]
        return np.concatenate(parts)

    def vjp(w):
        """``J^T w``: the residual cotangent ``w`` pulled back to z, one sweep per segment."""
        parts = np.split(np.asarray(w, dtype=float).ravel(), ends[:-1])
        gx, gv = np.zeros_like(trajectory.x), np.zeros_like(trajectory.v)
        terms.state_vjp(trajectory, parts, gx, gv)
        scaled = [r * part for r, part in zip(root, parts[len(terms):])]
        pulled = s.pull_back(runner, gx, gv, list(zip(scaled[::2], scaled[1::2])))
        pulled[:s.m] = terms.control_vjp(parts, pulled[:s.m])
        return pulled

    return Linearization(np.concatenate(pieces), jvp, vjp, size=z.size,
                         trajectory=trajectory, release=runner.close)

