r"""Reynolds-style flock: agents as particles with pairwise steering forces.

For a pair (i, j) let ``d = x_j - x_i``, ``dv = v_j - v_i`` and the regularised distance
``r = sqrt(|d|^2 + eps^2)`` (``eps`` keeps the direction finite when two agents coincide).
The force that j exerts on i is

* collision avoidance   ``f_a = -k_a g_a(r) d / r``            (repulsive, radius R_a)
* velocity matching     ``f_m =  k_m w(r; R_m) dv``             (damps relative velocity)
* flock centering       ``f_c =  k_c w(r; R_c) d``              (pulls toward neighbours)

and i exerts ``-f`` on j, so internal forces sum to zero.  Summing ``f_c`` over neighbours
is ``k_c W_i (c_i - x_i)``: an attraction to the w-weighted centre ``c_i`` of the
neighbourhood, linear as in the paper.  Two cut-offs:

* ``"hard"`` (the paper's): ``g_a = R_a - r``, ``w = 1`` inside the radius, 0 outside.
  Avoidance is continuous at R_a; matching and centering jump there.
* ``"smooth"`` (default): ``g_a = (R_a - r)^2 / R_a``, ``w = (1 - r^2/R^2)^2``; every force
  and its derivative vanish at its radius, which L-BFGS-B and IPOPT prefer.

Each agent also feels linear drag ``-c v`` and a stored wander force (see
:func:`wander_forces`): the total is ``f(x, v) + wander_n``.

The pair law is one SX kernel ``(d, dv) -> f``; its reverse-mode derivative gives the
transposed Jacobian-vector products the adjoint needs, so the flock Jacobian is never
assembled.  Neighbours come from a k-d tree (``scipy.spatial.cKDTree.query_pairs``), so a
force evaluation costs O(N) for a flock of bounded density.
"""
from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np
from scipy.spatial import cKDTree

from ..kernels import MappedKernel, pair_difference, pair_incidence, scatter_pairs
from .base import ForceDerivatives, Model

CUTOFFS = ("smooth", "hard")


@dataclass(frozen=True)
class FlockParams:
    """Strengths (k) and radii (R) of the flock's steering forces."""

    avoid_strength: float = 20.0
    avoid_radius: float = 1.0
    match_strength: float = 0.5
    match_radius: float = 2.5
    center_strength: float = 0.02
    center_radius: float = 4.0
    drag: float = 0.0
    cutoff: str = "smooth"
    eps: float = 1e-3

    def __post_init__(self):
        if self.cutoff not in CUTOFFS:
            raise ValueError(f"cutoff must be one of {CUTOFFS}, got {self.cutoff!r}")
        for name in ("avoid_radius", "match_radius", "center_radius", "eps"):
            if not getattr(self, name) > 0:
                raise ValueError(f"FlockParams.{name} must be positive, got {getattr(self, name)}")
        for name in ("avoid_strength", "match_strength", "center_strength", "drag"):
            if not getattr(self, name) >= 0:
                raise ValueError(f"FlockParams.{name} must be non-negative")

    @property
    def max_radius(self) -> float:
        return max(self.avoid_radius, self.match_radius, self.center_radius)


def _window(r, radius, cutoff):
    inside = r < radius
    if cutoff == "hard":
        return ca.if_else(inside, 1.0, 0.0)
    return ca.if_else(inside, (1 - (r / radius) ** 2) ** 2, 0.0)


def pair_force_expr(d, dv, p: FlockParams):
    """Force on agent i from agent j as a CasADi expression of ``d`` and ``dv``."""
    r = ca.sqrt(ca.dot(d, d) + p.eps ** 2)
    ra = p.avoid_radius
    gap = ra - r
    g_a = gap if p.cutoff == "hard" else gap ** 2 / ra
    f = -p.avoid_strength * ca.if_else(r < ra, g_a, 0.0) * d / r
    f += p.match_strength * _window(r, p.match_radius, p.cutoff) * dv
    f += p.center_strength * _window(r, p.center_radius, p.cutoff) * d
    return f


def pair_kernels(dim: int, p: FlockParams) -> dict[str, ca.Function]:
    """The pair force kernel and its derivative kernels, ``{"force", "vjp", "jvp"}``:

    ``force(d, dv) -> f``, ``vjp(d, dv, lam) -> (d(lam.f)/dd, d(lam.f)/d dv)`` and
    ``jvp(d, dv, dd, ddv) -> df`` (the derivative of f along ``(dd, ddv)``).
    """
    d, dv = ca.SX.sym("d", dim), ca.SX.sym("dv", dim)
    lam, dd, ddv = (ca.SX.sym(s, dim) for s in ("lam", "dd", "ddv"))
    f = pair_force_expr(d, dv, p)
    s = ca.dot(lam, f)
    return {
        "force": ca.Function("flock_pair", [d, dv], [f]),
        "vjp": ca.Function("flock_pair_vjp", [d, dv, lam],
                           [ca.gradient(s, d), ca.gradient(s, dv)]),
        "jvp": ca.Function("flock_pair_jvp", [d, dv, dd, ddv],
                           [ca.jtimes(f, ca.vertcat(d, dv), ca.vertcat(dd, ddv))]),
    }


def wander_forces(steps: int, n: int, dim: int, *, strength: float, seed: int,
                  correlation: float = 0.9) -> np.ndarray:
    """Random wander forces, drawn once so the objective is the same at every iteration.

    An AR(1) process per agent (``w_{n+1} = c w_n + sqrt(1-c^2) xi``, ``xi ~ N(0, 1)``):
    each component has standard deviation ``strength`` and varies smoothly when ``c`` is
    near 1.  Returns ``(steps, n, dim)``.
    """
    if not 0 <= correlation < 1:
        raise ValueError(f"wander correlation must be in [0, 1), got {correlation}")
    rng = np.random.default_rng(seed)
    out = np.empty((steps, n, dim))
    w = rng.standard_normal((n, dim))
    c, s = correlation, np.sqrt(1 - correlation ** 2)
    for k in range(steps):
        out[k] = w
        w = c * w + s * rng.standard_normal((n, dim))
    return strength * out


@dataclass(frozen=True)
class PairTape:
    """What one force evaluation remembers for its adjoint: the interacting pairs ``(i, j)``,
    in the order the forces were summed (so the adjoint sums in the same order).

    A simulation keeps one tape per step, the bulk of the adjoint's memory on a large flock:
    :meth:`compact` stores the indices in the smallest unsigned type that holds every agent
    (2 bytes an index up to 65536 agents, 4 up to 2**32, instead of 8).
    """

    i: np.ndarray
    j: np.ndarray

    @classmethod
    def compact(cls, i: np.ndarray, j: np.ndarray, n: int) -> "PairTape":
        """The pairs ``i, j`` of agents ``0..n-1`` in the smallest index type for ``n``."""
        dtype = np.min_scalar_type(max(n - 1, 0))
        return cls(i.astype(dtype), j.astype(dtype))


class FlockModel(Model, ForceDerivatives):
    """An immutable flock of ``len(masses)`` agents in ``dim`` (2 or 3) dimensions."""

    def __init__(self, masses, dim: int = 2, params: FlockParams | None = None,
                 jit: bool | None = None):
        m = np.array(masses, dtype=float)
        if m.ndim != 1 or m.size < 1:
            raise ValueError("masses must be a non-empty 1-D array (one mass per agent)")
        if not np.all(np.isfinite(m)) or np.any(m <= 0):
            raise ValueError("every agent mass must be positive and finite")
        if dim not in (2, 3):
            raise ValueError(f"a flock lives in 2 or 3 dimensions, got dim={dim}")
        m.flags.writeable = False
        params = FlockParams() if params is None else params
        kernels = pair_kernels(dim, params)
        for name, value in (("masses", m), ("dim", dim), ("params", params), ("jit", jit),
                            ("_kernels", kernels)):
            object.__setattr__(self, name, value)
        for k in ("force", "vjp", "jvp"):
            object.__setattr__(self, f"_{k}", MappedKernel(kernels[k], jit=jit))

    def __setattr__(self, name, value):
        raise AttributeError(f"a FlockModel is immutable: build a new one instead of setting "
                             f"{name!r}")

    @property
    def n(self) -> int:
        return self.masses.size

    # -- numeric -----------------------------------------------------------------------
    def neighbour_pairs(self, x: np.ndarray) -> PairTape:
        """Pairs (i < j) closer than the largest force radius, by a k-d tree; compact."""
        pairs = cKDTree(x).query_pairs(self.params.max_radius, output_type="ndarray")
        return PairTape.compact(pairs[:, 0], pairs[:, 1], self.n)

    interactions = neighbour_pairs  # the Model protocol's name: what one state's forces use

    def all_pairs(self) -> PairTape:
        """Every pair (i < j): the slow reference the neighbour list must reproduce."""
        i, j = np.triu_indices(self.n, k=1)
        return PairTape(i, j)

    def _pairs(self, a, tape):
        return pair_difference(a, tape.i, tape.j)

    def forces(self, x: np.ndarray, v: np.ndarray, t: float = 0.0,
               interactions: PairTape | None = None) -> np.ndarray:
        """Internal force on every agent, ``(n, dim)``, over the pairs ``interactions``
        (default: the neighbour pairs of x)."""
        tape = self.neighbour_pairs(x) if interactions is None else interactions
        (fp,) = self._force(self._pairs(x, tape), self._pairs(v, tape))
        return scatter_pairs(fp, tape.i, tape.j, self.n) - self.params.drag * v

    def forces_vjp(self, x: np.ndarray, v: np.ndarray, t: float, interactions: PairTape,
                   mu: np.ndarray):
        """``((df/dx)^T mu, (df/dv)^T mu)`` at (x, v), each ``(n, dim)``."""
        tape = interactions
        lam = -self._pairs(mu, tape)
        gd, gdv = self._vjp(self._pairs(x, tape), self._pairs(v, tape), lam)
        gx = scatter_pairs(-gd, tape.i, tape.j, self.n)
        gv = scatter_pairs(-gdv, tape.i, tape.j, self.n) - self.params.drag * mu
        return gx, gv

    def forces_jvp(self, x: np.ndarray, v: np.ndarray, t: float, interactions: PairTape,
                   dx: np.ndarray, dv: np.ndarray) -> np.ndarray:
        """``(df/dx) dx + (df/dv) dv`` at (x, v), ``(n, dim)``."""
        tape = interactions
        (dfp,) = self._jvp(self._pairs(x, tape), self._pairs(v, tape), self._pairs(dx, tape),
                           self._pairs(dv, tape))
        return scatter_pairs(dfp, tape.i, tape.j, self.n) - self.params.drag * dv

    # -- symbolic ----------------------------------------------------------------------
    def symbolic_forces(self, X, V, S=None):
        """All-pairs internal forces as a CasADi expression; X, V are ``dim x n`` (S, the
        scene parameters, is empty for a flock)."""
        tape = self.all_pairs()
        if tape.i.size == 0:
            return -self.params.drag * V
        forces = self._kernels["force"].map(tape.i.size)(X[:, tape.j] - X[:, tape.i],
                                                 V[:, tape.j] - V[:, tape.i])
        return ca.mtimes(forces, pair_incidence(tape.i, tape.j, self.n)) - self.params.drag * V

