"""The search in positions (DESIGN.md section 3d): the control problem transcribed with the
free particles' positions at every frame as the unknowns, the forces following from them by
the inverse of the problem's own step, least control cost as the objective and the goal as
constraints.

* :mod:`.transcription`: the problem in positions, its forces and their sparse Jacobian;
* :mod:`.goal`: the keyframes' tolerances as constraints on the positions;
* :mod:`.strain`: the problem's strain limit as a penalty in the positions;
* :mod:`.sqp`: the search, a sequential quadratic programme on the effort's Gauss-Newton
  matrix, and :mod:`.restore`: its correction for the stiff springs;
* :mod:`.interior`: the same problem by IPOPT (``solver=ipopt``), with :mod:`.stretch` (the
  physical stretch limit as constraints) and :mod:`.curvature` (the effort's exact
  Hessian, ``hessian=exact``);
* :mod:`.defects` and :mod:`.collocation`: where the controls are fewer than a force per
  free particle (initial velocities, forces on some particles), the positions and the
  controls as unknowns with every step an equality constraint, by IPOPT;
* :mod:`.replay`: controls that move the simulation along planned positions;
* :mod:`.method`: the search as the method ``"transcription"`` of ``METHODS``.
"""
from .transcription import Transcription, TranscriptionError, check_transcribable

__all__ = ["Transcription", "TranscriptionError", "check_transcribable"]
