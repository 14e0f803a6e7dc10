"""The accuracy studies' grids through the sweep runner (``casadi-keyframe study NAME
--grid ...``): each point is one row of the study, computed on a worker, kept in its
folder like a solve's point, so a large grid can use a cluster and ``--resume``.

    from casadi_keyframe.sweep import study_sweep
    result = study_sweep("gradient-accuracy", {"dt": [1/30, 1/60], "stretch": [50, 500]},
                         out="results/study", workers=2)
    result.rows   # one dict per point: dt, stretch, relative_error, cosine, ...
"""
from __future__ import annotations

import json
from pathlib import Path

from ..loading import OverrideError, check_overrides
from ..models import COLLISIONS
from ..sweep.grid import Point, folder_name, points
from ..sweep.plan import (Plan, SweepResult, check_grid, check_group_by, run_plan,
                          study_module)
from .accuracy import one_step_point, swapped_vs_exact
from .swap_validity import assembled, map_points, point_key, swap_validity_point

# name: (the function computing one row, the ranges of its keywords, the figures to rank by)
STUDIES = {
    "gradient-accuracy": (swapped_vs_exact,
                          {"dt": "(0, inf)", "horizon": "(0, inf)", "stretch": "(0, inf)",
                           "amplitude": "[0, inf)", "seed": "[0, inf)"},
                          ("relative_error",)),
    "integrator-accuracy": (one_step_point,
                            {"dt": "(0, inf)", "stretch": "(0, inf)", "rows": "[2, inf)",
                             "seed": "[0, inf)"},
                            ("gap_x", "gap_v")),
    "swap-validity": (swap_validity_point,
                      {"contact": ("none", "ground", "sphere", "capsule", "self"),
                       "collision": COLLISIONS,
                       "stiffness": "(0, inf)", "dt": "(0, inf)", "amplitude": "[0, inf)",
                       "horizon": "(0, inf)", "speed": "[0, inf)", "damping": "[0, inf)",
                       "rows": "[2, inf)", "maxiter": "[1, inf)", "seed": "[0, inf)",
                       "measure": ("horizon", "step")},
                      ("relative_error", "growth_swapped", "cosine")),
}


def _study(study: str):
    """``(target, module, figures)`` of a study: its function's ``"module:name"`` (what a
    worker imports), a module whose ``build`` is that function (checked like a problem
    file), the figures it ranks by."""
    if study not in STUDIES:
        raise ValueError(f"unknown study {study!r}; choose one of {', '.join(STUDIES)}")
    function, ranges, figures = STUDIES[study]
    target = f"{function.__module__}:{function.__qualname__}"
    return target, study_module(study, function, ranges), figures


def study_sweep(study: str, grid: dict, *, out, overrides: dict | None = None,
                figure: str | None = None, group_by=None, **runner) -> SweepResult:
    """Run the study ``study`` (a key of :data:`STUDIES`) at every combination of
    ``grid``'s values on top of ``overrides``; ``runner`` as for :func:`.plan.sweep`
    (``workers``, ``scheduler``, ``tries``, ``resume``, ``progress``)."""
    target, module, figures = _study(study)
    overrides = dict(overrides or {})
    try:
        grid = check_grid(module, grid, overrides)
        specs = [{"kind": "study", "function": target, "values": p.values, "start": 0,
                  "name": p.name, "label": p.label,
                  "overrides": check_overrides(module, {**overrides, **p.values})}
                 for p in points(grid)]
    except OverrideError as err:  # not a problem file: no 'show' hint
        raise ValueError(str(err)) from None
    figure = figure or figures[0]
    if figure not in figures:
        raise ValueError(f"--figure {figure!r}: the {study} study ranks by "
                         f"{', '.join(figures)}")
    group_by = check_group_by(group_by or [], list(grid))
    about = {"study": study, "grid": grid, "overrides": overrides}
    return run_plan(Plan(specs, Path(out), list(grid), figure, group_by, about), **runner)


def study_points(study: str, values: list, *, out, **runner) -> SweepResult:
    """Run the study ``study`` at each of ``values`` (dicts of its keywords, each point's
    own: a map made of slices that no one grid spans, such as
    :func:`~.swap_validity.map_points`); a point given twice runs once, and
    ``runner`` as for :func:`study_sweep`."""
    target, module, figures = _study(study)
    specs = {}
    try:
        for v in values:
            name = folder_name(v)
            specs.setdefault(name, {"kind": "study", "function": target, "values": dict(v),
                                    "start": 0, "name": name, "label": Point(v).label,
                                    "overrides": check_overrides(module, dict(v))})
    except OverrideError as err:
        raise ValueError(str(err)) from None
    keys = [k for k in dict.fromkeys(k for v in values for k in v)
            if len({json.dumps(v.get(k), default=str) for v in values}) > 1]
    about = {"study": study, "points": len(specs)}
    return run_plan(Plan(list(specs.values()), Path(out), keys, figures[0], [], about),
                    **runner)


def swap_validity_map(quick: bool | None = None, **runner) -> dict:
    """The swap-validity map (:func:`~.swap_validity.swap_validity`) with its points run on
    the sweep runner (``runner``: ``out``, ``workers``, ``scheduler``, ...), each kept in
    its folder; ``sweep`` says how the runner ended."""
    slices = map_points(quick)
    result = study_points("swap-validity", [p for ps in slices.values() for p in ps],
                          **runner)
    by_key = {point_key(r): r for r in result.rows}
    study = assembled({name: [by_key.get(point_key(p), {**p, "reason": "not run"})
                              for p in points] for name, points in slices.items()})
    study["sweep"] = {"exit_code": result.exit_code, "failed": len(result.failed)}
    return study
