"""The residual family: the objective as residuals, ``0.5 |r|^2``, linearized at a point, and
what the searches on residuals (Gauss-Newton, least squares, the finish's land and effort
steps) need of it.

* :mod:`.linearization`: the linearization (``r``, ``J p``, ``J^T w``) and the space a
  residual search moves in.
"""
