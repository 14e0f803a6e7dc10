"""The gallery's files: one page per problem in problems/, its pictures and measured result
collected from a results folder, so that building the site never runs a solve.

    casadi-keyframe solve cloth_shapes --out results/cloth_shapes    # one per problem
    python docs/gallery.py                   # collect every results/<problem>/ there is
    python docs/gallery.py cloth_toss --results /elsewhere           # some, from elsewhere

For each problem with a results folder (``summary.json`` and ``result.npz``, as ``solve``
writes them) it copies the pictures into ``docs/gallery/<problem>/`` and writes there
``measured.json``: the commit the script ran at (``git rev-parse --short HEAD``, with
``-dirty`` for uncommitted changes; ``--commit`` names another), the date, the overrides, the
status, iterations, seconds, each keyframe's miss against its tolerance (the library's own
verdict, on the saved trajectory) and how physical the result is.  Then it writes every
problem's page, ``docs/gallery/<problem>.md``, from the problem file's docstring and its
``measured.json`` (a problem never measured gets a page that says so), and the gallery's
index.  A run with ``--set`` overrides is marked on its page as a placeholder at a reduced
size.  Run it with the library installed (it rebuilds each problem to judge its keyframes).
"""
from __future__ import annotations

import argparse
import datetime
import json
import math
import shutil
import subprocess
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
GALLERY = ROOT / "docs" / "gallery"
PICTURES = ("keyframes.png", "start_and_result.png", "convergence.png", "animation.gif")
MAX_ANIMATION_BYTES = 3_000_000  # a larger animation.gif stays in the results folder
MISS_KEYS = {"rms_position_error": ("rms position", 0), "position_error": ("position", 0),
             "rms_velocity_error": ("rms velocity", 1), "velocity_error": ("velocity", 1),
             "fraction_inside": ("fraction inside", None)}


def commit_of(root: Path = ROOT) -> str:
    """``git rev-parse --short HEAD`` of ``root``, ``-dirty`` added when its tracked files
    differ from that commit (then the result is not that commit's)."""
    head = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=root, check=True,
                          capture_output=True, text=True).stdout.strip()
    dirty = subprocess.run(["git", "diff", "--quiet", "HEAD", "--", "casadi_keyframe",
                            "problems"], cwd=root).returncode
    return head + ("-dirty" if dirty else "")


def keyframe_rows(problem, trajectory) -> list[dict]:
    """Each keyframe term's misses, tolerances and whether it is met, judged by the term
    itself (``shortfall``) on ``trajectory``."""
    rows = []
    for term in problem.objective_terms.state_terms:
        miss = term.miss(trajectory)
        within = getattr(term, "within", None) or (None, None)
        tolerances = {}
        for key in miss:
            if key in MISS_KEYS and MISS_KEYS[key][1] is not None:
                tolerances[key] = within[MISS_KEYS[key][1]]
        if "fraction_inside" in miss:
            tolerances["fraction_inside"] = getattr(term, "fill", None)
        rows.append({"term": term.label, "miss": {k: v for k, v in miss.items() if k in MISS_KEYS},
                     "tolerance": tolerances, "goal": bool(term.has_tolerance),
                     "hit": term.shortfall(trajectory) is None})
    return rows


def physical(problem, trajectory, summary: dict) -> dict | None:
    """How physical a cloth's result is: the largest stretch and the deepest particle in a
    body, the problem's limits (``problem.limits``) and whether the motion keeps within
    them (the problem's own verdict); None for a model that reports no such thing."""
    report = summary.get("breakdown", {}).get("physical")
    limits = getattr(problem, "limits", None)
    if report is None:
        return None
    return {"max_stretch": report["max_stretch"],
            "max_penetration": report.get("max_penetration"),
            "stretch_limit": getattr(limits, "stretch", None),
            "depth_limit": getattr(limits, "depth", None),
            "broken": list(problem.physical_shortfall(trajectory)) if limits else []}


def measure(folder: Path, commit: str) -> dict:
    """``measured.json``'s record of the run in ``folder``."""
    from casadi_keyframe.saved import load_saved, read_run

    summary = json.loads((folder / "summary.json").read_text())
    run = load_saved(folder, quiet=True)
    overrides = summary.get("overrides", {})
    command = " ".join([f"casadi-keyframe solve {summary['problem']}",
                        *(f"--set {k}={v}" for k, v in overrides.items())])
    return {"problem": summary["problem"], "commit": commit,
            "date": datetime.date.today().isoformat(), "command": command,
            "overrides": overrides, "status": summary["status"],
            "status_name": summary["status_name"], "message": summary["message"],
            "iterations": summary["nit"], "evaluations": summary.get("nfev"),
            "wall_seconds": summary["timings"]["wall_seconds"],
            "method": summary.get("method"), "gradient": summary.get("gradient"),
            "stages": len(summary.get("stages", [])),
            "keyframes": keyframe_rows(run.problem, run.trajectory),
            "physical": physical(run.problem, run.trajectory, summary),
            "effort": run.problem.effort(read_run(folder)["u"])}


def collect(name: str, results: Path, commit: str) -> bool:
    """Copy ``results/name``'s pictures and write its ``measured.json``; False when there
    is no finished run to collect."""
    folder = results / name
    if not (folder / "summary.json").is_file():
        return False
    out = GALLERY / name
    if out.exists():
        shutil.rmtree(out)
    out.mkdir(parents=True)
    for picture in PICTURES:
        source = folder / picture
        if source.is_file() and (picture != "animation.gif"
                                 or source.stat().st_size <= MAX_ANIMATION_BYTES):
            shutil.copy2(source, out / picture)
    record = measure(folder, commit)
    (out / "measured.json").write_text(json.dumps(record, indent=2) + "\n")
    return True


def _number(value) -> str:
    if value is None:
        return "-"
    if isinstance(value, float) and not math.isfinite(value):
        return "not checked"
    return f"{value:.3g}"


def miss_table(rows: list[dict]) -> list[str]:
    """The keyframes' misses against their tolerances as a Markdown table."""
    lines = ["| keyframe | miss | tolerance | verdict |", "|---|---|---|---|"]
    for row in rows:
        misses = " / ".join(f"{MISS_KEYS[k][0]} {_number(v)}" for k, v in row["miss"].items())
        tolerances = " / ".join(_number(row["tolerance"].get(k)) for k in row["miss"])
        verdict = ("**HIT**" if row["hit"] else "**MISSED**") if row["goal"] else "not in the goal"
        lines.append(f"| `{row['term']}` | {misses} | {tolerances} | {verdict} |")
    return lines


def physical_lines(report: dict | None) -> list[str]:
    """The cloth's stretch and depth against the problem's physical limits, as a line."""
    if report is None:
        return []
    limit = report["stretch_limit"]
    text = f"Largest spring stretch {report['max_stretch']:.3f}" + (
        f" (limit {limit:g})" if limit else "")
    if report["max_penetration"] is not None:
        depth = report["depth_limit"]
        text += (f"; deepest particle in a body {report['max_penetration'] * 1e3:.2g} mm"
                 + (f" (tolerance {depth * 1e3:g} mm)" if depth else ""))
    verdict = ("**WHOLE**: within its physical limits" if not report["broken"] else
               "**NOT WHOLE**: " + "; ".join(report["broken"]))
    return [f"{text}. {verdict}.", ""]


def measured_section(name: str, record: dict | None) -> list[str]:
    """The page's "Measured" section: the result with its commit, or why there is none."""
    if record is None:
        return ["!!! warning \"Not yet measured\"",
                f"    No run of `{name}` has been collected yet: solve it with the command "
                "above and run `python docs/gallery.py`.", ""]
    lines = []
    if record["overrides"]:
        lines += ["!!! warning \"Placeholder at a reduced size\"",
                  f"    Measured with `{record['command']}`, not at the problem's defaults; "
                  "the default run replaces it.", ""]
    seconds = record["wall_seconds"]
    lines += [f"Measured at commit `{record['commit']}` on {record['date']} "
              f"(`{record['command']}`): **{record['status_name']}** (status "
              f"{record['status']}) after {record['iterations']} iterations"
              f" in {record['stages']} stage{'s' if record['stages'] != 1 else ''}, "
              f"{seconds:.0f} s of wall time, {record['method']} on the "
              f"`{record['gradient']}` gradient.", "", f"> {record['message']}", ""]
    lines += miss_table(record["keyframes"]) + [""]
    lines += physical_lines(record.get("physical"))
    if record.get("effort"):
        lines += [f"Effort: rms control acceleration "
                  f"{record['effort']['rms_acceleration']:.3g} m/s^2 per particle, peak "
                  f"{record['effort']['peak_acceleration']:.3g} m/s^2.", ""]
    return lines


def page(name: str, module, record: dict | None) -> str:
    """A problem's gallery page: what it is (its docstring), its picture, the command and
    what was measured."""
    import inspect

    from casadi_keyframe.loading import first_sentence, solve_defaults

    doc = inspect.cleandoc(module.__doc__ or "")
    lead, paragraphs = first_sentence(doc), doc.split("\n\n")
    after = " ".join(paragraphs[0].split())[len(lead):].strip()
    rest = "\n\n".join(([after] if after else []) + paragraphs[1:])
    pictures = [p for p in PICTURES if (GALLERY / name / p).is_file()]
    lines = [f"# {name}", "", f"*{lead}*", ""]
    if "keyframes.png" in pictures:
        lines += [f"![{name}: the result at its keyframes]({name}/keyframes.png)", ""]
    lines += ["## The problem", "", rest or f"Its file is `problems/{name}.py`.", "",
              "## The command", "", "```sh", f"casadi-keyframe solve {name} --out results/{name}",
              "```", "", f"Its solve defaults (`SOLVE`): `{solve_defaults(module)}`; "
              f"`casadi-keyframe show {name}` lists every override with its type, default and "
              "range.", "", "## Measured", ""]
    lines += measured_section(name, record)
    captions = {"start_and_result.png": "The search's start and its result at the keyframes",
                "convergence.png": "The search: objective, keyframe error and control cost "
                                   "per iteration",
                "animation.gif": "The whole motion"}
    for picture in pictures[1:] if "keyframes.png" in pictures else pictures:
        lines += [f"![{captions[picture]}]({name}/{picture})", "", f"*{captions[picture]}.*", ""]
    notes = (ROOT / "docs" / "problem_notes.md").read_text()
    if f"\n## {name}\n" in notes:
        lines += [f"Why its defaults are what they are, measured: [problem notes]"
                  f"(../problem_notes.md#{name}).", ""]
    return "\n".join(lines)


def index(entries: list[tuple[str, str, dict | None]]) -> str:
    """The gallery's front page: every problem, its picture and its verdict."""
    lines = ["# Gallery", "", "One page per problem shipped in `problems/`: what it is, its "
             "picture, the command that solves it and its measured result with the commit "
             "it came from.  The pictures and figures are files collected from results "
             "folders by `docs/gallery.py`; building the site never runs a solve.  To measure "
             "them again, on the commit to publish:", "", "```sh",
             "for f in problems/*.py; do p=$(basename $f .py); "
             "casadi-keyframe solve $p --out results/$p; done",
             "python docs/gallery.py          # pictures and figures into docs/gallery/", "```",
             "",
             "| problem | what | result | commit |", "|---|---|---|---|"]
    for name, lead, record in entries:
        if record is None:
            result, commit = "not yet measured", "-"
        else:
            hits = sum(r["hit"] for r in record["keyframes"] if r["goal"])
            goals = sum(r["goal"] for r in record["keyframes"])
            result = (f"{record['status_name']}, {hits} of {goals} keyframes hit"
                      + (" (placeholder, reduced size)" if record["overrides"] else ""))
            commit = f"`{record['commit']}`"
        lines.append(f"| [{name}]({name}.md) | {lead} | {result} | {commit} |")
    lines += [""] + blender_section() + ['<div class="grid cards" markdown>', ""]
    for name, _, _ in entries:
        if (GALLERY / name / "keyframes.png").is_file():
            lines += [f"-   [![{name}]({name}/keyframes.png)]({name}.md)", "",
                      f"    [{name}]({name}.md)", ""]
    return "\n".join(lines + ["</div>", ""])


def blender_section() -> list[str]:
    """The add-on's rigged example as ``blender/make_rig_screenshot.py`` left it (its
    picture and ``rigged_cape.json``), or nothing where it was never made."""
    record_path = GALLERY / "rigged_cape.json"
    if not record_path.is_file():
        return []
    record = json.loads(record_path.read_text())
    return ["## In Blender", "",
            "The add-on's rigged example (`blender/rigged_cape.py`): a cape sewn at the "
            "shoulders of a character that walks and turns, its pinned vertices carried by "
            "the armature, a target pose as a shape key "
            "([how it is set up](../guides/meshes-and-blender.md#a-cape-on-a-rigged-character)),"
            f" solved by the add-on in Blender and rendered headless by "
            f"`{record['command']}` at commit `{record['commit']}`: "
            f"{record['misses']}; {record['seconds']:.0f} s.", "",
            "![The rigged cape in Blender: the start, on the way, the keyframe with its "
            "target in red](rigged_cape.png)", ""]


def write_pages() -> list[str]:
    """Every problem's page and the index, from the problem files and ``measured.json``."""
    from casadi_keyframe.loading import first_sentence, list_problems, load_module

    entries = []
    for name, _ in list_problems():
        measured = GALLERY / name / "measured.json"
        record = json.loads(measured.read_text()) if measured.is_file() else None
        module = load_module(name)
        (GALLERY / f"{name}.md").write_text(page(name, module, record))
        entries.append((name, first_sentence(module.__doc__ or ""), record))
    (GALLERY / "index.md").write_text(index(entries))
    return [name for name, _, _ in entries]


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("problems", nargs="*", help="problems to collect (default: every "
                        "problem with a results folder)")
    parser.add_argument("--results", type=Path, default=ROOT / "results",
                        help="folder holding one results folder per problem (default results/)")
    parser.add_argument("--commit", help="the commit the runs came from (default: this "
                        "checkout's, git rev-parse --short HEAD)")
    args = parser.parse_args(argv)
    from casadi_keyframe.loading import list_problems

    names = args.problems or [name for name, _ in list_problems()]
    commit = args.commit or commit_of()
    GALLERY.mkdir(parents=True, exist_ok=True)
    for name in names:
        done = collect(name, args.results, commit)
        print(f"{name}: {'collected at ' + commit if done else 'no results folder, kept as it was'}")
    write_pages()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
