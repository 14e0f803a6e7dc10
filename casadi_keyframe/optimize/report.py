"""One-line reports of a search, for the terminal, summaries and exports: a stage's or a
round's outcome, the keyframes' misses, how physical a motion stays."""
from __future__ import annotations

def format_stage(stage: dict) -> str:
    """One line for a continuation stage (its dt, the build overrides that made it: a
    coarser mesh, a homotopy level) or an augmented-Lagrangian round (its weight scale and
    keyframe misses), ending with how it stopped; a stage that did not run says why."""
    made = ", ".join(f"{k}={typed(v)}" for k, v in stage.get("overrides", {}).items())
    head = (f"round {stage['stage']}: weight x{stage['weight_scale']:.3g}"
            if "weight_scale" in stage else
            f"stage {stage['stage']}{f' ({made})' if made else ''}: dt {stage['dt']:.6g} s, "
            f"{stage['steps']} steps"
            + (f", {stage['particles']} particles" if "particles" in stage else ""))
    if "skipped" in stage:
        return f"{head}; {stage['message']}"
    line = (f"{head}, {stage['nit']} iterations, objective {stage['fun']:.6g}, "
            f"{stage['seconds']:.1f} s")
    if stage.get("misses"):
        line += "; " + format_misses(stage["misses"])
    return line + (f"; {stage['message']}" if stage.get("message") else "")


def typed(value) -> str:
    """An override's value as typed: a number as written (3, not 3.0), a sequence
    comma-separated."""
    if isinstance(value, (list, tuple)):
        return ",".join(typed(v) for v in value)
    return f"{value:g}" if isinstance(value, float) else str(value)


def format_physical(report: dict) -> str:
    """``physical: largest stretch 1.16 (frame 30), deepest in a body 4.1 mm (frame 52)``
    (no depth for a cloth without colliders)."""
    text = (f"physical: largest stretch {report['max_stretch']:.3g} (frame "
            f"{report['max_stretch_frame']})")
    if "max_penetration" in report:
        text += (f", deepest in a body {1e3 * report['max_penetration']:.3g} mm (frame "
                 f"{report['max_penetration_frame']})")
    return text


def format_misses(misses) -> str:
    """``"StateKeyframe@60 over 416 particles: rms_position_error 0.01, ..."``, terms
    separated by "; " (an rms is over the particles named)."""
    def head(m):
        return m["term"] + (f" over {m['particles']} particles:" if "particles" in m else "")

    return "; ".join(head(m) + " " + ", ".join(f"{k} {v:.4g}" for k, v in m.items()
                                               if k not in ("term", "particles"))
                     for m in misses)


def format_effort(effort: dict) -> str:
    """``effort: rms 22 m/s^2, peak 178 m/s^2 per particle`` (the control forces over the
    pushed particles' masses)."""
    return (f"effort: rms {effort['rms_acceleration']:.3g} m/s^2, peak "
            f"{effort['peak_acceleration']:.3g} m/s^2 per particle")
