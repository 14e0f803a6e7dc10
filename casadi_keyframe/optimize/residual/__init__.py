"""The residual family: the objective as residuals, ``0.5 |r|^2``, linearized at a point, and
what the searches on residuals (Gauss-Newton, least squares, the finish's land and effort
steps) build from it: a descent times a step-size rule, as optimistix pairs them.

* :mod:`.linearization`: :class:`~.linearization.Linearization`, the one linearization
  (``r``, ``J p``, ``J^T w``, the run, the first frame a change moves), and its producer for
  a problem's objective; multiple shooting's merit and the finish's held keyframes make the
  same type;
* :mod:`.descents`: the steps a linearization gives (the Gauss-Newton model's CG path, the
  least-norm landing, the projected Newton step of a quadratic cost);
* :mod:`.steps`: the step-size rules (trust radius, halving, damping);
* :mod:`.space`: where a residual search moves (the evaluator's variables, bounds,
  products in them).
"""
