"""The ``solve`` command's options for multiple shooting and the homotopy stages: their
arguments and how their values are read (kept apart from :mod:`.cli`, which holds the
commands)."""
from __future__ import annotations


def add_shooting_options(s, whole) -> None:
    """``--segments``, ``--shooting``, ``--scheduler`` and ``--homotopy`` on the parser
    ``s`` (``whole``: the argparse type of a whole number >= 1)."""
    s.add_argument("--segments", type=whole, metavar="K",
                   help="multiple shooting with K segments: the controls and the states where "
                        "segments meet searched together, the segments' defects held by "
                        "multipliers (1: single shooting, not the problem file's default)")
    s.add_argument("--shooting", action="append", metavar="KEY=VALUE,...",
                   help="multiple shooting's options: init=passive|guess|target|blend (where "
                        "the node states start), workers=N (processes sweeping the segments, "
                        "default 1), rounds=N, formulation=lagrangian|ipopt (the defects as "
                        "IPOPT's constraints), penalty=X, growth=X, polish=True|False")
    s.add_argument("--scheduler", metavar="ADDRESS",
                   help="sweep the segments on the running Dask cluster at ADDRESS (e.g. "
                        "tcp://10.0.0.5:8786) instead of local processes")
    s.add_argument("--homotopy", action="append", metavar="KEY=VALUE,...",
                   help="solve first with the model changed by these build overrides, e.g. "
                        "contact=3 (a cape's contact three times softer and thicker); repeat, "
                        "first to last; the problem's own model ends each mesh")


def parse_shooting(segments, items: list[dict], scheduler) -> dict | None:
    """``--segments K``, the ``--shooting`` items (each read as a dict) and ``--scheduler
    ADDRESS`` as multiple shooting's options over the problem file's (None: the file's);
    checked here, so a bad one is refused before the build."""
    from .optimize.shooting import shooting_options

    out = {} if segments is None else {"segments": segments}
    for item in items:
        out.update(item)
    if scheduler is not None:
        out["scheduler"] = scheduler
    if not out:
        return None
    shooting_options({"segments": 2, **out})  # every option checked (the count later)
    return out


def parse_levels(module, items: list[dict]) -> list[dict] | None:
    """The ``--homotopy`` items (each read as a dict) as build overrides, each checked
    against the problem's ``build``; None without any."""
    from .loading import check_overrides

    if not items:
        return None
    for item in items:
        if not item:
            raise ValueError("--homotopy expects KEY=VALUE,... such as contact=3")
    return [check_overrides(module, item) for item in items]
