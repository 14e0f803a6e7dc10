"""Studies that measure the library itself: the gradient routes' and integrators' accuracy
(:mod:`.accuracy`), a gradient's health at a point (:mod:`.health_report`), the map of where
the paper's swapped adjoint suffices (:mod:`.swap_validity`), and their grids run on the
sweep runner (:mod:`.sweeps`)."""
