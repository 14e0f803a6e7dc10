r"""Mass-spring cloth's springs with the Choi-Ko (2002) buckling response.

For a spring (i, j) of rest length ``L`` let ``d = x_j - x_i``, ``dv = v_j - v_i``, the
regularised length ``r = sqrt(|d|^2 + eps^2)`` and ``u = d / r``.  The force on particle i is

* tension, ``r >= L``:      ``f_i = k_t (r - L) u``                 (pulls i toward j)
* compression, ``r < L``:   ``f_i = -k_b kappa^2 u``               (pushes the ends apart)
* damping, always:          ``f_i += c ((dv . u) u)``

and j feels ``-f_i``, so internal forces sum to zero.  Under compression the spring is
assumed to buckle into a circular arc of length L with chord r, so its curvature solves
``r / L = sinc(kappa L / 2)`` (``sinc(y) = sin(y) / y``), i.e. ``kappa^2 = 4 y^2 / L^2``
with ``y = sinc^{-1}(s)``, ``s = r / L``.  ``z = y^2`` is analytic in ``w = 1 - s`` on
[0, 1] (``z ~ 6 w`` near rest), so it is fitted once as ``z(w) = w P(w)`` with P a
degree-10 polynomial (:data:`SINC_INV_COEFFS`, |y error| < 1e-5): the force vanishes at
``r = L`` exactly and no square root appears in the kernel.

No strut-like resistance before buckling.  The law's radial stiffness jumps at ``r = L``
from ``k_t`` to the buckling slope ``24 k_b / L^3``, so the linearized step's matrix jumps
when a spring passes its rest length (the objective is only piecewise smooth there).  A
compressive force that resisted like a strut instead (stiffness ``k_t`` over a few percent of
strain) gives every compressed spring a transverse stiffness ``m / r < 0`` large enough to
make a flat, compressed sheet (a sheet hanging in its plane) a buckling saddle: the passive
sheet stays exactly planar, and the gradient of any keyframe objective grows by orders of
magnitude per second of simulated time along it
(``tests/test_cloth_model.py::test_flat_hanging_sheet_has_a_meaningful_gradient``).  Real
cloth buckles at a tiny load, which is what the Choi-Ko law says.

Spring kinds (:data:`SPRING_KINDS`) and their stiffnesses come from the cloth's
:class:`~.cloth.ClothParams`: stretch and shear springs take ``k_t`` from ``stretch`` and
``shear``; bend springs (skip one particle, or across an interior edge) have
``k_t = 24 bend / L^3``, the slope of the buckling force at ``r = L``, so their force is C^1
across the rest length.  Every kind buckles with ``k_b = bend``.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import casadi as ca
import numpy as np

from ..kernels import interaction_kernels
from .interaction import PairInteraction

SPRING_KINDS = ("stretch", "shear", "bend")
STRETCH, SHEAR, BEND = range(3)
# a spring within this relative distance of its rest length counts as at rest (tension
# branch): the law's kink there must not be decided by round-off, which differs between the
# numeric and symbolic routes for states at rest up to it (a sheet at rest, or translating)
REST_TOLERANCE = 1e-9
# a spring a step ends this far past its rest length, having got this much longer within
# the step (relative), was linearized too softly: it is taken taut
TAUT_MARGIN = 0.05
# the step is solved again with such springs taut only if one of them ends this far past its
# rest length; else they are taut from the next step on, and the step stands
REDO_MARGIN = 0.2


def _fit_sinc_inverse(degree: int = 10) -> np.ndarray:
    """Coefficients of P (highest power first) with ``sinc^{-1}(1 - w)^2 ~= w P(w)``."""
    y = np.pi * (1 - np.cos(np.linspace(0, np.pi, 4001)[1:])) / 2  # dense at both ends
    w = 1 - np.sin(y) / y
    return np.polyfit(w, y ** 2 / w, degree)


SINC_INV_COEFFS = _fit_sinc_inverse()


def sinc_inverse_squared(s):
    """``y^2`` with ``sinc(y) = s`` for s in [0, 1]; numpy arrays or CasADi expressions."""
    w = 1 - s
    acc = 0 * w + SINC_INV_COEFFS[0]
    for c in SINC_INV_COEFFS[1:]:  # Horner
        acc = acc * w + c
    return w * acc


def sinc_inverse(s: np.ndarray) -> np.ndarray:
    """``y`` in [0, pi] with ``sin(y) / y = s``, for s in [0, 1] (numpy)."""
    return np.sqrt(np.maximum(sinc_inverse_squared(np.asarray(s, dtype=float)), 0.0))


def spring_law(d, dv, L, k_t, k_b, c, taut, eps: float, band: float = 0.0):
    """``(f_i, K)`` of one spring as CasADi expressions (see the module docstring): the force
    on particle i and the stiffness ``K ~ df_i/dd`` the implicit step uses.

    With magnitude ``m(r)`` and ``f_i = m u``: ``df_i/dd = m' u u^T + m (I/r - d d^T/r^3)``.
    Under compression ``m < 0`` and the transverse term is negative: it says a compressed
    spring would rather rotate than shorten, and at fine resolution it makes the step matrix
    ``M - dt D - dt^2 K`` indefinite.  As Choi and Ko, K keeps it only under tension
    (``max(m, 0)``); ``m' >= 0`` on both branches, so K is negative semi-definite and the
    step matrix positive definite for every dt.

    ``taut`` (0 or 1) is the step's decision to take the spring taut: then its K is
    ``k_t I``, the tension stiffness in every direction.  Linearized at its start a spring
    resists only along its length (and nothing while it is at or under its rest length: the
    buckling slope is tens of times softer, the transverse term vanishes at rest), so a step
    in which one end stops and the other does not, as when a cloth hits a body, stretches it
    unchecked; the step finds the springs it overstretched (:data:`TAUT_MARGIN`) and solves
    again with them taut.  The force is the law's either way.

    ``band`` > 0 (:attr:`~.cloth.ClothParams.rest_band`) makes K continuous in the state:
    see :func:`rest_lack`.  ``band = 0`` is the paper's step.
    """
    r = ca.sqrt(ca.dot(d, d) + eps ** 2)
    u = d / r
    tension = r >= L * (1 - REST_TOLERANCE)
    m = ca.if_else(tension, k_t * (r - L), buckling_magnitude(r, L, k_b))
    force = m * u + c * ca.dot(dv, u) * u
    transverse = ca.fmax(m, 0) * (ca.SX.eye(3) / r - ca.mtimes(d, d.T) / r ** 3)
    radial = ca.mtimes(u, ca.jacobian(m, d))
    if band > 0:
        radial = radial + ca.if_else(tension, 0, rest_lack(r, L, k_t, k_b, band)) * ca.mtimes(
            u, u.T)
    stiffness = ca.if_else(taut > 0.5, k_t * ca.SX.eye(3), radial + transverse)
    return force, stiffness


def buckling_magnitude(r, L, k_b):
    """The law's force magnitude ``-k_b kappa^2`` under compression (CasADi or numpy)."""
    return -k_b * 4 * sinc_inverse_squared(r / L) / L ** 2


def rest_lack(r, L, k_t, k_b, band: float):
    """The radial stiffness a compressed spring of length ``r`` lacks against the tension
    stiffness, ``max(k_t - m_b'(r), 0)`` (``m_b`` the buckling magnitude), blended in by a
    smoothstep from 0 at ``(1 - band) L`` to 1 at ``L``.

    The law's radial stiffness jumps at rest from ``k_t`` to the buckling slope, and the
    linearized step takes its matrix at the step's start: a spring whose start length
    crosses rest between two runs switches the step's matrix, so the motion is a
    discontinuous function of the controls.  With the lack added over the band the step's
    matrix is a continuous (C^1 along the spring) function of the state, every route
    differentiating it exactly; the force is the law's, so this is another linearization
    of the same model, not another model.  Bend springs (``k_t`` the buckling slope at
    rest) lack nothing."""
    s = ca.SX.sym("s")
    slope = ca.substitute(ca.jacobian(buckling_magnitude(s * L, L, k_b), s), s, r / L) / L
    t = ca.fmin(ca.fmax((r / L - (1 - band)) / band, 0), 1)
    return t * t * (3 - 2 * t) * ca.fmax(k_t - slope, 0)


def spring_kernels(eps: float, band: float = 0.0) -> dict[str, ca.Function]:
    """``force(d, dv, L, k_t, k_b, c, taut) -> f_i``, ``jac(...) -> (vec K, vec D)``
    (row-major) and
    the derivative kernels (see :func:`~casadi_keyframe.kernels.interaction_kernels`), K from
    :func:`spring_law` (``band``: its rest band).  As Baraff and Witkin, the damping force's
    position derivative (not symmetric) is left out of K, so K is symmetric."""
    d, dv = ca.SX.sym("d", 3), ca.SX.sym("dv", 3)
    scalars = [ca.SX.sym(name) for name in ("L", "k_t", "k_b", "c", "taut")]
    force, stiffness = spring_law(d, dv, *scalars, eps, band)
    return interaction_kernels("cloth_spring", d, dv, scalars, force, stiffness)


@dataclass(frozen=True)
class Springs:
    """Springs as parallel arrays: endpoints ``i``, ``j``, ``rest`` length (m) and ``kind``
    (index into SPRING_KINDS)."""

    i: np.ndarray
    j: np.ndarray
    rest: np.ndarray
    kind: np.ndarray

    def count(self, kind: str) -> int:
        return int(np.sum(self.kind == SPRING_KINDS.index(kind)))

    def stretch(self, x: np.ndarray) -> np.ndarray:
        """Every spring's length over its rest length at positions ``x`` (``(..., n, 3)``)."""
        x = np.asarray(x)
        d = np.take(x, self.j, axis=-2)
        d -= np.take(x, self.i, axis=-2)
        return np.sqrt(np.einsum("...a,...a->...", d, d)) / self.rest


@dataclass(frozen=True)
class TautSprings:
    """What a step decided for the springs: ``now`` (a bool per spring), those its matrix
    takes taut, and ``later`` (None: none), those it stretched too far too fast but not far
    enough to be solved again (:data:`REDO_MARGIN`), taut from the next step on."""

    now: np.ndarray
    later: np.ndarray | None = None


class ChoiKoSprings(PairInteraction):
    """The cloth's springs as a family: the Choi-Ko law over fixed pairs.

    ``stiffness`` is ``(stretch, shear, bend)`` of :class:`~.cloth.ClothParams`, ``damping``
    the along-spring damping c, ``eps`` the length regularisation, ``rest_band`` the
    step's rest band (:func:`rest_lack`; 0: the paper's step).  What a step decides for
    them (its ``found``) is which springs it takes taut (:func:`spring_law`): a
    :class:`TautSprings`, or None for none."""

    name = "springs"
    role = "internal"

    def __init__(self, springs: Springs, n: int, *, stiffness: tuple, damping: float,
                 eps: float, rest_band: float = 0.0, jit: bool | None = None):
        super().__init__(spring_kernels(eps, rest_band), n, jit)
        stretch, shear, bend = stiffness
        self.springs = springs
        k_t = np.choose(springs.kind, [stretch, shear, 0.0]).astype(float)
        k_t = np.where(springs.kind == BEND, 24 * bend / springs.rest ** 3, k_t)
        size = springs.rest.size
        self.parameters_per_spring = (springs.rest[:, None], k_t[:, None],
                                      np.full((size, 1), bend), np.full((size, 1), damping))
        for a in self.parameters_per_spring:
            a.flags.writeable = False
        self._ij = (springs.i, springs.j)
        self._slack = np.zeros((size, 1))

    def pairs(self, found):
        return self._ij

    def pair_parameters(self, i, j, found=None):
        taut = self._slack if found is None else found.now.astype(float)[:, None]
        return [*self.parameters_per_spring, taut]

    def symbolic_pair_parameters(self, i, j, decisions=None):
        rows = [ca.DM(np.asarray(a).T) for a in self.parameters_per_spring]
        taut = ca.DM(self._slack.T) if decisions is None else ca.reshape(decisions, 1, i.size)
        return rows + [taut]

    def decision_parameters(self, found, t, dt):
        """The taut flags (0/1 per spring) the symbolic blocks take."""
        return np.zeros(self.springs.i.size) if found is None else found.now.astype(float)

    def decide(self, step, carried):
        """The springs a step at x keeps taut from the last (``carried``, taut flags): those
        still stretched past their rest length (None if none)."""
        if carried is None:
            return None
        kept = carried & (self._stretch(step.x) > 1)
        return TautSprings(kept) if kept.any() else None

    def carry(self, found):
        """The springs taut now or from the next step on (a bool array; None: none)."""
        if found is None:
            return None
        return found.now if found.later is None else found.now | found.later

    def revise(self, found, end, stopped):
        """``found`` with the :meth:`late` springs taken taut if one of them ends beyond
        ``1 + REDO_MARGIN`` times its rest length at ``end.x1`` (the step is solved again);
        None if none does (:meth:`settle` defers them)."""
        late, end_stretch = self.late(found, end, stopped)
        if late is None or not (end_stretch[late] > 1 + REDO_MARGIN).any():
            return None
        taut = late if found is None else found.now | late
        return TautSprings(taut, None if found is None else found.later)

    def settle(self, found, end, stopped):
        """``found`` with the :meth:`late` springs of a step that stands taken taut from the
        next step on."""
        late, _ = self.late(found, end, stopped)
        if late is None:
            return found
        if found is None:
            return TautSprings(np.zeros_like(late), late)
        return replace(found, later=late if found.later is None else found.later | late)

    def late(self, found, end, stopped):
        """``(late, end stretch)``: where a step stopped particles (``stopped``: a stop
        within a step stretches springs; elsewhere taking them taut would make an objective
        rough for nothing), the springs not yet taut that end beyond ``1 + TAUT_MARGIN``
        times their rest length at ``end.x1`` having got longer by that much over the step
        (smooth motion changes a spring's length slowly; a step that missed a stop does
        not), and the stretched springs sharing a particle with one; ``late`` None if
        none."""
        if not stopped:
            return None, None
        s = self.springs
        end_stretch = end.kept((id(self), "x1"), lambda: self._stretch(end.x1))
        start_stretch = end.kept((id(self), "x"), lambda: self._stretch(end.x))
        late = (end_stretch > 1 + TAUT_MARGIN) & (end_stretch > start_stretch + TAUT_MARGIN)
        if late.any():  # and the springs around them, which a taut one would stretch next
            near = np.zeros(self.n, bool)
            near[s.i[late]] = near[s.j[late]] = True
            late |= (near[s.i] | near[s.j]) & (end_stretch > 1)
        if found is not None:
            late &= ~found.now
        return (late, end_stretch) if late.any() else (None, None)

    def _stretch(self, x):
        """:meth:`Springs.stretch` at x, remembered for the last few positions asked (a
        step's start is asked at every revision and was the last step's end)."""
        memory = self.__dict__.setdefault("_stretches", [])
        for kept, value in memory:
            if kept.shape == x.shape and np.array_equal(kept, x):
                return value
        value = self.springs.stretch(x)
        memory.insert(0, (np.array(x), value))
        del memory[3:]
        return value

    def all_pairs(self):
        return self._ij
