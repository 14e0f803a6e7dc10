r"""Multiple shooting for keyframe problems: the horizon in K segments, the state at the
start of each later segment an unknown, continuity between segments a constraint.

The unknowns are the controls and the node states' free components, scaled by the
keyframes' tolerances (:func:`defect_scales`) so that a defect as large as the tolerance is
a unit change; each segment starts from what the step before it carried beyond the state,
so consistent nodes give the single run exactly.  The scaled defects enter through the
:class:`~..multipliers.Multipliers` the keyframe rounds use too, and every derivative is
exact: each segment's backward sweep carries the stitched frames' objective derivatives
and its defect's weight back to its forces and its start.  The whole account:
``docs/explanations/multiple_shooting.md``.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from ...state import State, Trajectory
from .segments import boundaries, same_carry


class Shooting:
    """The multiple-shooting form of ``problem`` with ``segments`` segments.

    ``reference``: a trajectory of the problem (any controls) whose frames give the
    prescribed components of the node states; ``scales``: ``(sigma_x, sigma_v)``, the
    defects' units (default :func:`defect_scales`); ``spans``: the segments' ``(first,
    last)`` frames (default ``segments`` equal ones, :func:`~.segments.boundaries`).
    """

    def __init__(self, problem, segments: int, reference: Trajectory, scales=None,
                 spans=None):
        self.problem = problem
        self.spans = boundaries(problem.steps, segments) if spans is None else list(spans)
        self.K = len(self.spans)
        n, dim = problem.model.n, problem.model.dim
        self.free = np.asarray(problem.model.free_mask(), bool).reshape(n, dim)
        self.nf = int(self.free.sum())
        self.sigma = tuple(float(s) for s in (scales or defect_scales(problem)))
        self.reference = [State(reference.x[a].copy(), reference.v[a].copy())
                          for a, _ in self.spans[1:]]
        self.m = problem.size
        self.size = self.m + 2 * self.nf * (self.K - 1)
        self.carried = [None] * self.K  # what each segment started from at the last sweep
        self.rerun = 0  # segments swept again because their guessed carry was wrong

    # -- the variables ---------------------------------------------------------------------
    def pack(self, u, nodes) -> np.ndarray:
        """``z`` from controls ``u`` and the node states (``K - 1`` States, full arrays)."""
        sx, sv = self.sigma
        parts = [np.asarray(u, float).ravel()]
        for s in nodes:
            parts += [s.x[self.free] / sx, s.v[self.free] / sv]
        return np.concatenate(parts)

    def unpack(self, z):
        """``(u, nodes)`` of ``z``: node States with their prescribed components filled in."""
        sx, sv = self.sigma
        u, rest = z[:self.m], z[self.m:].reshape(self.K - 1, 2, self.nf)
        nodes = []
        for ref, (y, w) in zip(self.reference, rest):
            x, v = ref.x.copy(), ref.v.copy()
            x[self.free], v[self.free] = sx * y, sv * w
            nodes.append(State(x, v))
        return u, nodes

    def unpack_change(self, dz):
        """``(du, [(dx, dv), ...])``: a change of z as the controls' change and each node's
        state change (full arrays, zero in the prescribed components)."""
        sx, sv = self.sigma
        du, rest = dz[:self.m], dz[self.m:].reshape(self.K - 1, 2, self.nf)
        return du, [(self._full(sx * y), self._full(sv * w)) for y, w in rest]

    def bounds(self):
        lb, ub = self.problem.bounds()
        pad = np.full(self.size - self.m, np.inf)
        return np.concatenate([lb, -pad]), np.concatenate([ub, pad])

    def nodes_of(self, traj: Trajectory) -> list:
        """The node states a trajectory passes through (consistent nodes: no defect)."""
        return [State(traj.x[a].copy(), traj.v[a].copy()) for a, _ in self.spans[1:]]

    # -- one evaluation --------------------------------------------------------------------
    def starts_and_forces(self, u, nodes):
        """Each segment's start State and its steps' external forces."""
        p = self.problem
        offset, forces = p.controls.velocity_offset(u), p.controls.external(u)
        v0 = p.v0 if offset is None else p.v0 + offset
        ext = p.external if forces is None else p.external + forces
        starts = [State(p.x0, v0)] + list(nodes)
        return starts, [ext[a:b] for a, b in self.spans]

    def stitch(self, frames) -> Trajectory:
        """The trajectory made of each segment's own frames (its start up to the next
        node's frame; the last segment's up to the end)."""
        x = np.empty((self.problem.steps + 1,) + self.free.shape)
        v = np.empty_like(x)
        for k, ((a, b), (fx, fv)) in enumerate(zip(self.spans, frames)):
            end = b + 1 if k == self.K - 1 else b
            x[a:end], v[a:end] = fx[:end - a], fv[:end - a]
        return Trajectory(x, v, self.problem.dt)

    def defects(self, frames, nodes) -> list:
        """Scaled defects ``(c_x, c_v)`` of segments 0 .. K-2 (free components)."""
        sx, sv = self.sigma
        return [((fx[-1][self.free] - s.x[self.free]) / sx,
                 (fv[-1][self.free] - s.v[self.free]) / sv)
                for (fx, fv), s in zip(frames[:-1], nodes)]

    def evaluate(self, z, runner, mult):
        """``(merit, gradient, info)`` at ``z``: the problem's objective on the stitched
        trajectory plus the defects' augmented-Lagrangian terms (``mult``, blocks ``(k,
        "x")`` and ``(k, "v")``), exact; ``info`` has the objective, its keyframe part, the
        scaled defects and the stitched trajectory.  ``runner`` sweeps the segments
        (:class:`~.workers.Serial` or a pool); ``mult`` None leaves the defects out."""
        p, (sx, sv) = self.problem, self.sigma
        u, nodes = self.unpack(np.asarray(z, float))
        starts, ext = self.starts_and_forces(u, nodes)
        frames = self.sweep(runner, starts, ext)
        traj = self.stitch(frames)
        value, gx, gv = p.state_cost(traj)
        control, g_control = p.control_cost(u)
        c = self.defects(frames, nodes)
        if mult is None:  # the objective alone (the defects as constraints elsewhere)
            merit, weighed = value + control, [(0 * cx, 0 * cv) for cx, cv in c]
        else:
            merit = value + control + sum(mult.value((k, "x"), cx) + mult.value((k, "v"), cv)
                                          for k, (cx, cv) in enumerate(c))
            weighed = [(mult.gradient((k, "x"), cx), mult.gradient((k, "v"), cv))
                       for k, (cx, cv) in enumerate(c)]
        grad = self.pull_back(runner, gx, gv, weighed)
        grad[:self.m] += g_control
        info = {"objective": value + control, "keyframe_error": value, "defects": c,
                "trajectory": traj}
        return merit, grad, info

    def pull_back(self, runner, gx, gv, weighed) -> np.ndarray:
        """d/dz of the stitched frames' cotangents ``gx, gv`` (``(steps + 1, n, dim)``) and
        the scaled defects' ``weighed`` (``(w_x, w_v)`` per defect), through the segments'
        last forward passes (``runner``): one backward sweep per segment."""
        p, (sx, sv) = self.problem, self.sigma
        pulls = [(self._full(wx / sx), self._full(wv / sv)) for wx, wv in weighed]
        cotangents = []
        for k, (a, b) in enumerate(self.spans):
            gxk, gvk = gx[a:b + 1].copy(), gv[a:b + 1].copy()
            if k < self.K - 1:  # frame b is the next node's; the segment's end is the defect's
                gxk[-1], gvk[-1] = pulls[k]
            cotangents.append((gxk, gvk))
        pulled = runner.backward(cotangents)
        g_ext = np.concatenate([g for g, _ in pulled])
        grad = [p.controls.pullback(g_ext, pulled[0][1].v)]
        for k in range(1, self.K):
            start = pulled[k][1]
            grad += [sx * (start.x[self.free] - pulls[k - 1][0][self.free]),
                     sv * (start.v[self.free] - pulls[k - 1][1][self.free])]
        return np.concatenate(grad)

    def sweep(self, runner, starts, ext) -> list:
        """Each segment's frames ``(x, v)`` from ``starts`` under ``ext``, each starting
        from what the previous segment's last step carried: the segments run at once from
        the carries of the last sweep, then, in order, any whose carry was wrong runs again
        from the right one (a runner in this process chains them and needs none)."""
        out = runner.forward({k: (s, e, self.carried[k] if k else None)
                              for k, (s, e) in enumerate(zip(starts, ext))})
        for k in range(1, self.K):
            carry = out[k - 1][3]
            if not same_carry(out[k][2], carry):
                self.rerun += 1
                out.update(runner.forward({k: (starts[k], ext[k], carry)}))
        self.carried = [out[k][2] for k in range(self.K)]
        return [out[k][:2] for k in range(self.K)]

    def defect_vector(self, c) -> np.ndarray:
        """The scaled defects ``[c_x(0), c_v(0), c_x(1), ...]`` as one vector."""
        return np.concatenate([np.concatenate(pair) for pair in c]) if c else np.zeros(0)

    def defect_jacobian(self, runner) -> sp.csr_matrix:
        """d (:meth:`defect_vector`) / dz at the point :meth:`evaluate` last ran (its
        forward passes kept where they ran): one backward sweep per row over its segment,
        the row's end-state unit cotangent pulled back to the segment's forces and start."""
        sx, sv = self.sigma
        units = np.flatnonzero(self.free.ravel())
        ends = {}
        for k in range(self.K - 1):
            rows = []
            for scale, kind in ((sx, 0), (sv, 1)):
                for i in units:
                    e = np.zeros(self.free.size)
                    e[i] = 1.0 / scale
                    zero = np.zeros(self.free.shape)
                    pair = (e.reshape(self.free.shape), zero) if kind == 0 else (
                        zero, e.reshape(self.free.shape))
                    rows.append(pair)
            ends[k] = rows
        pulled = runner.rows(ends)
        blocks, p, steps = [], self.problem, self.problem.steps
        for k in range(self.K - 1):
            a, b = self.spans[k]
            dense = np.zeros((2 * self.nf, self.size))
            for r, (g_ext, start) in enumerate(pulled[k]):
                full = np.zeros((steps,) + self.free.shape)
                full[a:b] = g_ext
                dense[r, :self.m] = p.controls.pullback(full, start.v if k == 0 else 0 * start.v)
                if k > 0:
                    col = self.m + 2 * self.nf * (k - 1)
                    dense[r, col:col + self.nf] = sx * start.x[self.free]
                    dense[r, col + self.nf:col + 2 * self.nf] = sv * start.v[self.free]
            col = self.m + 2 * self.nf * k
            dense[:, col:col + 2 * self.nf] -= np.eye(2 * self.nf)
            blocks.append(sp.csr_matrix(dense))
        return sp.vstack(blocks).tocsr() if blocks else sp.csr_matrix((0, self.size))

    def _full(self, free_values) -> np.ndarray:
        out = np.zeros(self.free.shape)
        out[self.free] = free_values
        return out

    def defect_size(self, c) -> float:
        """The largest segment's rms scaled defect (1: as large as the tolerance)."""
        if not c:
            return 0.0
        return max(float(np.sqrt(np.mean(np.concatenate([cx, cv]) ** 2))) for cx, cv in c)


def defect_scales(problem) -> tuple[float, float]:
    """The defects' units ``(sigma_x, sigma_v)``: the tightest position and velocity
    tolerances the problem's keyframes declare (a keyframe's rms miss, a centre's miss), or
    0.01 length units and 0.1 per second where none does."""
    from ...objectives.tolerances import DEFAULT_POSITION_TOLERANCE, VELOCITY_TIME

    found = {0: [], 1: []}
    for term in problem.objective_terms.state_terms:
        for i, value in enumerate(term.within or ()):
            if value is not None and np.isfinite(value):
                found[i].append(float(value))
    sx = min(found[0]) if found[0] else DEFAULT_POSITION_TOLERANCE
    sv = min(found[1]) if found[1] else sx / VELOCITY_TIME
    return sx, sv
