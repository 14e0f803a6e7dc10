"""Multiple shooting's merit as residuals, ``0.5 |r(z)|^2``, linearized at a point: what a
residual search (the Gauss-Newton trust region, scipy's ``least_squares``) needs of
:class:`~.merit.ShootingMerit`.

``r`` stacks the problem's residuals on the stitched trajectory (keyframe misses, strain
excess, control effort, as :class:`~..residuals.Linearization`) and each defect block's
``sqrt(w_b) (c_b + lambda_b / w_b)`` (:class:`~..multipliers.Multipliers`: its part of the
merit is half its square).  ``J p`` is one tangent pass per segment along its recorded run
(the integrators' exact ``step_jvp``), ``J^T w`` one backward sweep per segment
(:meth:`~.form.Shooting.pull_back`, the merit's own).  The segments run in this process,
on a runner of their own (the evaluator's runner moves with its trial points).
"""
from __future__ import annotations

import numpy as np

from ...simulate import tangent
from ..residual.linearization import ResidualMap, TermResiduals
from .segments import Shifted
from .workers import Serial


class ShootingLinearization(ResidualMap):
    """The residual map of ``merit`` (a :class:`~.merit.ShootingMerit` with multipliers) at
    ``z``: :attr:`residual`, :attr:`value`, :meth:`jvp`, :meth:`vjp`, :meth:`release`, as
    :class:`~..residuals.Linearization` gives them for a problem."""

    def __init__(self, merit, z):
        if merit.mult is None:
            raise ValueError("a residual search runs multiple shooting's augmented "
                             "Lagrangian (formulation 'lagrangian'), not its IPOPT form")
        self.shooting, self.mult = merit.shooting, merit.mult
        s, p = self.shooting, self.shooting.problem
        self.z = np.asarray(z, dtype=float)
        self.u, nodes = s.unpack(self.z)
        starts, ext = s.starts_and_forces(self.u, nodes)
        self.runner = Serial(p, s.spans)
        out = self.runner.forward({k: (st, e, None) for k, (st, e) in enumerate(zip(starts,
                                                                                    ext))})
        frames = [out[k][:2] for k in range(s.K)]
        self.trajectory = s.stitch(frames)
        self.terms = TermResiduals(p)
        self._blocks = [(k, c) for k in range(s.K - 1) for c in ("x", "v")]
        self._root = np.array([np.sqrt(self.mult.weights[b]) for b in self._blocks])
        defects = [c for pair in s.defects(frames, nodes) for c in pair]
        pieces = (self.terms.pieces(self.trajectory, self.u)
                  + [root * (c + self.mult.shift(b))
                     for root, c, b in zip(self._root, defects, self._blocks)])
        self._ends = np.cumsum([q.size for q in pieces])
        self.residual = np.concatenate(pieces)
        self.products = 0

    @property
    def shape(self) -> tuple:
        return (self.residual.size, self.z.size)

    def jvp(self, dz) -> np.ndarray:
        """``J dz``: one tangent pass per segment from its start's change."""
        s, p = self.shooting, self.shooting.problem
        du, dnodes = s.unpack_change(np.asarray(dz, dtype=float).ravel())
        offset, forces = p.controls.velocity_offset(du), p.controls.external(du)
        forces = np.zeros_like(p.external) if forces is None else forces
        starts = [(np.zeros_like(p.x0), np.zeros_like(p.v0) if offset is None else offset)]
        starts += [(dx, dv) for dx, dv in dnodes]
        frames = []
        for k, (a, b) in enumerate(s.spans):
            traj = self.runner.runner.kept[k]
            frames.append(tangent(Shifted(p.integrator, a), p.model, traj, *starts[k],
                                  forces[a:b]))
        moved = s.stitch(frames)
        parts = self.terms.jvp(self.trajectory, moved.x, moved.v, du)
        sx, sv = s.sigma
        for k, (dx, dv) in enumerate(frames[:-1]):
            node_x, node_v = starts[k + 1]
            parts += [self._root[2 * k] * (dx[-1] - node_x)[s.free] / sx,
                      self._root[2 * k + 1] * (dv[-1] - node_v)[s.free] / sv]
        self.products += 1
        return np.concatenate(parts)

    def vjp(self, w) -> np.ndarray:
        """``J^T w``: the residual cotangent ``w`` pulled back to z, one sweep per segment."""
        s = self.shooting
        parts = np.split(np.asarray(w, dtype=float).ravel(), self._ends[:-1])
        gx, gv = np.zeros_like(self.trajectory.x), np.zeros_like(self.trajectory.v)
        self.terms.state_vjp(self.trajectory, parts, gx, gv)
        scaled = [root * part for root, part in zip(self._root, parts[len(self.terms):])]
        out = s.pull_back(self.runner, gx, gv, list(zip(scaled[::2], scaled[1::2])))
        out[:s.m] = self.terms.control_vjp(parts, out[:s.m])
        self.products += 1
        return out

    def release(self) -> None:
        """Hand the segments' kept factorisations back."""
        self.runner.close()
