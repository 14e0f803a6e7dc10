""""exact": the deprecated name of the "casadi" route (CasADi reverse mode); it still works
and warns (DeprecationWarning)."""
from __future__ import annotations

import warnings

from .casadi_reverse import CasADiReverse


class Exact(CasADiReverse):
    """Deprecated name of :class:`CasADiReverse` ("casadi")."""

    replaced_by = CasADiReverse
    deprecation = ("gradient 'exact' is deprecated: it is CasADi reverse mode, now named "
                   "'casadi' (the hand-written exact adjoint is 'adjoint')")

    def __init__(self):
        warnings.warn(self.deprecation, DeprecationWarning, stacklevel=2)
