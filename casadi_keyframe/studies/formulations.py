"""Four ways to pose the same keyframe problem, side by side (``notebooks/formulations.ipynb``,
``casadi-keyframe study formulations``): single shooting with the exact adjoint, the paper's
swapped adjoint, multiple shooting, and the transcription (the search in positions), on
``mesh_keyframes`` from zero forces, each under the same iteration and time budget.

Each run is ``casadi-keyframe solve`` in its own process (:mod:`.formulation_run`: its CPU
seconds and peak memory are its own), and is judged here, in this process, from what it
wrote: the result's controls simulated again on the problem built again (the replay),
against the trajectory and the misses the run reported.  A row per run; the table has a
column per :class:`Formulation`, so another formulation is one more entry of
:data:`FORMULATIONS`.
"""
from __future__ import annotations

import contextlib
import io
import json
import os
import subprocess
import sys
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..adjoints import Adjoint, Swapped
from .formulation_run import MEASURED


@dataclass(frozen=True)
class Formulation:
    """One column: how ``casadi-keyframe solve`` is asked to solve (``method``,
    ``gradient``, the method's ``options``, multiple shooting's ``segments`` and its other
    ``shooting`` options)."""

    label: str
    method: str
    gradient: str | None = None
    options: dict = field(default_factory=dict)
    segments: int | None = None
    shooting: dict = field(default_factory=dict)

    @property
    def name(self) -> str:
        """The label as a folder name."""
        return "".join(c if c.isalnum() else "-" for c in self.label.lower()).strip("-")

    def given(self, budget: "Budget") -> dict:
        """The solve request's values (``solve_run``'s ``given``)."""
        return {"method": self.method, "gradient": self.gradient,
                "options": dict(self.options) or None,
                "shooting": {"segments": self.segments, **self.shooting} if self.segments
                else None,
                "maxiter": budget.maxiter, "time_limit": budget.time_limit}

    def flags(self, budget: "Budget") -> str:
        """The same request as ``casadi-keyframe solve``'s options."""
        said = [f"--method {self.method}"] + (
            [f"--gradient {self.gradient}"] if self.gradient else []) + [
            f"--option {k}={v}" for k, v in self.options.items()] + (
            [f"--segments {self.segments}"] if self.segments else []) + (
            ["--shooting " + ",".join(f"{k}={v}" for k, v in self.shooting.items())]
            if self.shooting else [])
        return " ".join(said + [f"--maxiter {budget.maxiter}",
                                f"--time-limit {budget.time_limit:g}"])


FORMULATIONS = (
    Formulation("single shooting, exact adjoint", "lbfgsb", Adjoint.name),
    Formulation("single shooting, swapped adjoint", "lbfgsb", Swapped.name),
    Formulation("multiple shooting, 4 segments", "lbfgsb", Adjoint.name, segments=4),
    Formulation("multiple shooting, 4 segments, 2 rounds", "lbfgsb", Adjoint.name, segments=4,
                shooting={"rounds": 2}),
    Formulation("transcription from rest", "transcription", options={"start": "rest"}),
    Formulation("transcription from zero forces", "transcription",
                options={"start": "controls"}),
    Formulation("least squares (the file's SOLVE)", "least-squares", Adjoint.name),
)
"""The columns, left to right: L-BFGS-B on the controls with each gradient route, multiple
shooting on L-BFGS-B (nodes from the zero-force run, ``init=passive``; its default eight
augmented-Lagrangian rounds share the iterations, two rounds give each more), the transcription
from the rest state held still and from the zero-force motion, and what the problem file's
``SOLVE`` runs from zero forces (scipy's trust-region least squares).  A column is one
entry: the transcription on another solver, once it takes one, would be
``Formulation("transcription, IPOPT", "transcription", options={"start": "rest",
"solver": "ipopt"})``."""


@dataclass(frozen=True)
class Budget:
    """The same for every run: iterations (``--maxiter``) and wall-clock seconds
    (``--time-limit``, counted from the run's start, after the build)."""

    maxiter: int
    time_limit: float


@dataclass(frozen=True)
class Case:
    """One problem: ``mesh_keyframes`` from zero forces (``guess=none``), its own 12 x 12
    sheet or a ``rows`` x ``rows`` sheet with the same targets (written as OBJ files, as a
    user hands them in)."""

    rows: int = 12

    @property
    def name(self) -> str:
        return f"mesh{self.rows}"

    @property
    def label(self) -> str:
        return f"mesh_keyframes {self.rows} x {self.rows}, from zero forces"

    def overrides(self, folder: Path) -> dict:
        """``mesh_keyframes``' build overrides (the sheet's files written into ``folder``)."""
        if self.rows == 12:
            return {"guess": "none"}
        from ..scenes.mesh_targets import write_sheet_and_targets

        files = write_sheet_and_targets(Path(folder) / self.name, self.rows, self.rows)
        return {"cloth": str(files["sheet"]), "pins": (0, self.rows - 1),
                "keyframes": f"40:{files['wave']},80:{files['fold']}", "guess": "none"}


def command(overrides: dict) -> str:
    """``casadi-keyframe solve mesh_keyframes --set ...`` with these build overrides."""
    sets = " ".join(f"--set {k}={','.join(map(str, v)) if isinstance(v, tuple) else v}"
                    for k, v in overrides.items())
    return f"casadi-keyframe solve mesh_keyframes {sets}"


def study_plan(quick: bool) -> tuple[tuple[Case, ...], Budget]:
    """The cases and the budget: the 12 x 12 and 8 x 8 sheets at 40 iterations and 600 s of
    wall clock (the iterations bind; the machine is shared, so the clock only guards); in
    quick mode 5 x 5 and 4 x 4 sheets at 2 iterations / 60 s."""
    if quick:
        return (Case(5), Case(4)), Budget(2, 60.0)
    return (Case(12), Case(8)), Budget(40, 600.0)


def run_study(cases, budget: Budget, folder, formulations=FORMULATIONS,
              progress=print) -> list[dict]:
    """Every formulation on every case under ``budget``, each run kept in ``folder``; a row
    per run (:func:`judge`), a failed run's row carrying its ``error``."""
    folder = Path(folder)
    rows = []
    for case in cases:
        for formulation in formulations:
            out = folder / case.name / formulation.name
            rows.append(run_one(case, formulation, budget, out))
            progress(f"{case.label}: {formulation.label}: {outcome(rows[-1])}")
    return rows


def run_one(case: Case, formulation: Formulation, budget: Budget, out) -> dict:
    """One run in its own process (one BLAS thread), judged."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    overrides = case.overrides(out.parent.parent)
    spec = out.with_suffix(".json")
    spec.write_text(json.dumps({"problem": "mesh_keyframes", "overrides": overrides,
                                "given": formulation.given(budget), "out": str(out)}))
    env = {**os.environ, "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1",
           "MKL_NUM_THREADS": "1"}
    done = subprocess.run([sys.executable, "-m", "casadi_keyframe.studies.formulation_run",
                           str(spec)], env=env, capture_output=True, text=True)
    (out.with_suffix(".log")).write_text(done.stdout + done.stderr)
    row = {"case": case.label, "formulation": formulation.label,
           "command": f"{command(overrides)} {formulation.flags(budget)}"}
    if done.returncode != 0 or not (out / MEASURED).is_file():
        tail = (done.stderr or done.stdout).strip().splitlines()[-1:] or ["no output"]
        return {**row, "error": f"the run failed (exit {done.returncode}): {tail[0]}"}
    return {**row, **json.loads((out / MEASURED).read_text()), **judge(overrides, out)}


def judge(overrides: dict, out) -> dict:
    """What the run in ``out`` reached, from its controls simulated again on the problem
    built again: each keyframe's miss and tolerance (mm), whether the goal is met, the
    largest stretch and its limit, the effort (rms and peak control acceleration per
    particle, m/s^2), and the replay's largest distance from the trajectory the run wrote
    and from the misses it reported (mm); with the run's iterations, status and message."""
    from ..loading import load_problem
    from ..optimize.goal import verdict
    from ..saved import read_run

    with contextlib.redirect_stderr(io.StringIO()):  # the build's notes are in the run's log
        prob = load_problem("mesh_keyframes", **overrides)
    run = read_run(out)
    replay = prob.simulate(run["u"], records=False)
    found = prob.breakdown(run["u"], replay)
    summary = json.loads((Path(out) / "summary.json").read_text())
    reported = [m["rms_position_error"] for m in summary["breakdown"]["misses"]]
    misses = [m["rms_position_error"] for m in found["misses"]]
    terms = prob.objective_terms.state_terms
    return {"misses_mm": [1e3 * m for m in misses],
            "tolerances_mm": [1e3 * t.within[0] for t in terms],
            "met": verdict(prob, replay).met,
            "stretch": found["physical"]["max_stretch"], "stretch_limit": prob.limits.stretch,
            "rms": found["effort"]["rms_acceleration"],
            "peak": found["effort"]["peak_acceleration"],
            "replay_mm": 1e3 * float(np.abs(replay.x - run["arrays"]["x"]).max()),
            "reported_mm": 1e3 * max(abs(a - b) for a, b in zip(misses, reported)),
            "nit": summary["nit"], "status": summary["status_name"],
            "message": summary["message"]}


def outcome(row: dict) -> str:
    """A run's one-line outcome."""
    if "error" in row:
        return row["error"]
    misses = "/".join(f"{m:.1f}" for m in row["misses_mm"])
    return (f"{misses} mm, rms {row['rms']:.1f} / peak {row['peak']:.0f} m/s^2, "
            f"{row['nit']} iterations, {row['cpu_seconds']:.0f} s CPU, exit {row['exit']}")


MEASURES = (
    ("misses mm (tolerance)", lambda r: "/".join(f"{m:.1f}" for m in r["misses_mm"])
     + f" ({'/'.join(f'{t:.0f}' for t in r['tolerances_mm'])})"),
    ("goal met", lambda r: "yes" if r["met"] else "no"),
    ("stretch (limit)", lambda r: f"{r['stretch']:.3f} ({r['stretch_limit']:g})"),
    ("effort rms / peak m/s^2", lambda r: f"{r['rms']:.1f} / {r['peak']:.0f}"),
    ("iterations", lambda r: str(r["nit"])),
    ("CPU s", lambda r: f"{r['cpu_seconds']:.0f}"),
    ("peak memory MB (after build)", lambda r: f"{r['peak_mb']:.0f} ({r['built_mb']:.0f})"),
    ("exit (status)", lambda r: f"{r['exit']} ({r['status']})"),
    ("replay vs run, mm", lambda r: f"{max(r['replay_mm'], r['reported_mm']):.1e}"),
)
"""The table's rows: a name and how a run's row says it."""


def table(rows: list[dict]) -> str:
    """A markdown table per case: a column per formulation, a line per :data:`MEASURES`."""
    blocks = []
    for case in dict.fromkeys(r["case"] for r in rows):
        runs = [r for r in rows if r["case"] == case]
        lines = [f"**{case}**", "", "| | " + " | ".join(r["formulation"] for r in runs) + " |",
                 "|---" * (len(runs) + 1) + "|"]
        for name, say in MEASURES:
            cells = ["failed" if "error" in r else say(r) for r in runs]
            lines.append(f"| {name} | " + " | ".join(cells) + " |")
        blocks.append("\n".join(lines))
    return "\n\n".join(blocks)


def messages(rows: list[dict]) -> str:
    """Each run's command line and its exit message (or why it failed)."""
    return "\n".join(f"* {r['case']}, {r['formulation']}: `{r['command']}`\n  "
                     f"{r.get('message', r.get('error'))}" for r in rows)


def plot(rows: list[dict]):
    """One figure: per case, each formulation's misses against the tolerance, its effort
    (rms and peak) and its CPU seconds; a failed run is left out."""
    import matplotlib.pyplot as plt

    cases = list(dict.fromkeys(r["case"] for r in rows))
    fig, axes = plt.subplots(len(cases), 3, figsize=(15, 3.6 * len(cases)), squeeze=False)
    for (a, b, c), case in zip(axes, cases):
        runs = [r for r in rows if r["case"] == case and "error" not in r]
        at = np.arange(len(runs))
        for k, shift in ((0, -0.2), (1, 0.2)):
            a.bar(at + shift, [r["misses_mm"][k] for r in runs], 0.4,
                  label=f"keyframe {k + 1}")
        if runs:
            a.axhline(runs[0]["tolerances_mm"][0], color="k", ls="--", lw=1, label="tolerance")
        b.bar(at - 0.2, [r["rms"] for r in runs], 0.4, label="rms")
        b.bar(at + 0.2, [r["peak"] for r in runs], 0.4, label="peak")
        c.bar(at, [r["cpu_seconds"] for r in runs], 0.6, color="gray")
        for ax, what in ((a, "miss (mm)"), (b, "control acceleration (m/s^2)"),
                         (c, "CPU s")):
            ax.set_yscale("log")
            ax.set_ylabel(what)
            ax.set_xticks(at, [r["formulation"] for r in runs], rotation=30, ha="right",
                          fontsize=8)
            ax.grid(True, axis="y", which="both", alpha=0.3)
        a.legend(fontsize=8)
        b.legend(fontsize=8)
        a.set_title(case, fontsize=10, loc="left")
    fig.tight_layout()
    return fig
