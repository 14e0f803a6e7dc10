"""The search in positions (DESIGN.md section 3d): the control problem transcribed with the
free particles' positions at every frame as the unknowns, the forces following from them by
the inverse of the problem's own step, least control cost as the objective and the goal as
constraints.

* :mod:`.transcription`: the problem in positions, its forces and their sparse Jacobian;
"""
from .transcription import Transcription, TranscriptionError, check_transcribable

__all__ = ["Transcription", "TranscriptionError", "check_transcribable"]
