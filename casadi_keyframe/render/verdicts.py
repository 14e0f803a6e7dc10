"""Whether each keyframe was hit, said on its panel: a line per keyframe naming it, its
misses in the units a user thinks in beside their tolerances, and HIT or MISSED in words on
a green or red label (never colour alone).

The verdict is the goal's own (:meth:`..objectives.markers.Marker.check`, which calls the term's
``shortfall`` as :func:`casadi_keyframe.optimize.goal.verdict` does): nothing here tests a
tolerance.  Lengths of a cloth (metres) read in mm and its speeds in cm/s; a flock's are in
its own length unit.
"""
from __future__ import annotations

import numpy as np
from matplotlib.transforms import offset_copy

HIT, MISSED, UNJUDGED = "#1e7b34", "#c0392b", "#6b6b6b"  # label colours (white text)
LINE, GAP = 1.3, 0.55  # font sizes per line of a panel's verdicts, and between two of them
SMALL, LARGE = 6.5, 8.5  # their font size in small multiples and in an animation


def checks_at(markers, trajectory, frame: int | None = None) -> list:
    """The :class:`..objectives.keyframe_goal.Check` of ``trajectory`` against each marker's keyframe at
    ``frame`` (None: at every frame); markers without a goal say nothing."""
    return [c for m in markers if frame is None or m.frame == frame
            if (c := m.check(trajectory)) is not None]


def last_keyframe(markers, n: int) -> int | None:
    """The latest keyframe frame at or before frame ``n`` (None before the first): an
    animation keeps saying how that keyframe went until the next one."""
    passed = [m.frame for m in markers if m.goal is not None and m.frame <= n]
    return max(passed) if passed else None


def format_mm(value: float) -> str:
    """A distance in mm to two significant figures (``"< 0.01 mm"`` below that)."""
    if value < 0.01:
        return "< 0.01 mm"
    return f"{value:.2g} mm" if value < 10 else f"{value:.0f} mm"


def format_value(value: float, quantity: str, metres: bool) -> str:
    """``value`` of ``quantity`` ("length", "speed" or "fraction") as a user reads it: with
    ``metres``, lengths in mm and speeds in cm/s; else in the model's own unit."""
    if quantity == "fraction":
        return f"{value:.0%}" if value in (0.0, 1.0) else f"{value:.1%}"
    if quantity == "length":
        return format_mm(1e3 * value) if metres else f"{value:.3g}"
    return f"{100 * value:.2g} cm/s" if metres else f"{value:.3g}/s"


def miss_phrase(miss, metres: bool) -> str:
    """``"rms miss 4.2 mm (tol 10 mm)"``, ``"inside 97.0% (goal \u2265 100%)"`` or, for a
    measure held to no tolerance, ``"max 9.1 mm"``."""
    value = format_value(miss.value, miss.quantity, metres)
    tolerance = miss.tolerance
    if tolerance is None or not np.isfinite(tolerance):
        return f"{miss.name} {value}"
    limit = format_value(tolerance, miss.quantity, metres)
    return (f"{miss.name} {value} (goal \u2265 {limit})" if miss.bound == "least"
            else f"{miss.name} {value} (tol {limit})")


def check_text(check, metres: bool, width: int = 200) -> str:
    """``"HIT  StateKeyframe@40: rms miss 4.2 mm (tol 10 mm), max 9.1 mm"``; longer than
    ``width`` characters, the misses go on lines of their own, as many as they need."""
    head = f"{check.verdict}  {check.label}"
    phrases = [miss_phrase(m, metres) for m in check.misses]
    if len(head) + sum(len(p) + 2 for p in phrases) <= width:
        return f"{head}: {', '.join(phrases)}"
    lines = [head]
    for i, phrase in enumerate(phrases):
        if i and len(lines[-1]) + len(phrase) + 2 <= width:
            lines[-1] += f", {phrase}"
        else:
            lines.append(phrase)
    return "\n".join(lines)


def verdict_color(check) -> str:
    """The colour of a check's label: green (HIT), red (MISSED), grey (no tolerance)."""
    return UNJUDGED if check.met is None else (HIT if check.met else MISSED)


def draw_checks(ax, checks, metres: bool, *, fontsize: float = SMALL,
                above: bool = False) -> list:
    """One label per check, white on green (HIT), red (MISSED) or grey (no tolerance),
    stacked down from the top left corner of ``ax`` (a 2-D or 3-D axes), or with ``above``
    stacked just above it (then pad the title by :func:`stack_height`); returns the
    artists."""
    text = getattr(ax, "text2D", ax.text)
    fig = ax.figure
    em = 0.62 * fontsize  # a bold character's mean width, in points
    width = int(ax.get_position().width * fig.get_figwidth() * 72 / em)
    labels = [check_text(c, metres, width) for c in checks]
    lines = np.cumsum([0] + [label.count("\n") + 1 for label in labels])
    top = stack_height(labels, fontsize) + 0.3 * fontsize if above else 0.0
    return [text(0.0 if above else 0.01, 1.0 if above else 0.99, label, fontsize=fontsize,
                 fontweight="bold", color="white", va="top", ha="left", zorder=20,
                 linespacing=1.15, clip_on=False,
                 transform=offset_copy(ax.transAxes, fig=fig, units="points",
                                       y=top - fontsize * (LINE * lines[i] + GAP * i)),
                 bbox=dict(boxstyle="round,pad=0.2", fc=verdict_color(check), ec="none",
                           alpha=0.92))
            for i, (check, label) in enumerate(zip(checks, labels))]


def say_checks(ax, markers, trajectory, n: int, *, metres: bool, hold: bool = False,
               large: bool = False, above: bool = False) -> list:
    """:func:`draw_checks` of the keyframes at frame ``n`` (with ``hold``, an animation's: at
    the latest keyframe frame up to ``n``), in a ``large`` font for an animation."""
    frame = last_keyframe(markers, n) if hold else n
    checks = [] if frame is None else checks_at(markers, trajectory, frame)
    return draw_checks(ax, checks, metres, fontsize=LARGE if large else SMALL, above=above)


def stack_height(labels, fontsize: float) -> float:
    """The height in points of the stacked ``labels`` (texts, or the artists of
    :func:`draw_checks`)."""
    texts = [label if isinstance(label, str) else label.get_text() for label in labels]
    lines = sum(t.count("\n") + 1 for t in texts)
    return fontsize * (LINE * lines + GAP * max(len(texts) - 1, 0)) if texts else 0.0


def titled(name: str, markers, trajectory, problem=None) -> str:
    """``"name: 3 of 4 keyframes hit"`` over the keyframes the goal judges (``name`` alone
    when it judges none), then what the motion breaks of ``problem``'s physical limits
    (``"; torn: stretch 1.88 at frame 2 (limit 1.3)"``), which the goal judges too."""
    judged = [c for c in checks_at(markers, trajectory) if c.met is not None]
    broken = [] if problem is None else problem.physical_shortfall(trajectory)
    hits = (f": {sum(c.met for c in judged)} of {len(judged)} "
            f"keyframe{'s' * (len(judged) > 1)} hit" if judged else "")
    return name + hits + "".join(f"; {b}" for b in broken)
