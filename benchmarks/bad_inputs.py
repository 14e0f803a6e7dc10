"""Every bad input a user may meet at the library's edges, and what each gets: damaged run
files given to each command, unwritable and odd output paths, problem files that fail,
loose Python API arguments, and the options and inputs of long runs (issue 42: the finish's
options, bodies that are no body or an open or mixed-wound one, keys given twice, a folder
in use, a stage no coarser than the problem, a time limit the start does not fit in).  Prints a Markdown table: the input, the command or call, the
exit code or exception, the message's first line, and whether the output held a traceback
or advice to load pickled data (both should say no).

Each command runs as a user runs it, in its own process; the API calls run here.

    .venv/bin/python benchmarks/bad_inputs.py [--out FOLDER]
"""
import argparse
import io
import subprocess
import sys
import tempfile
import zipfile
from pathlib import Path

import numpy as np

HERE = Path(sys.executable).parent
COMMAND = [str(HERE / "casadi-keyframe")] if (HERE / "casadi-keyframe").exists() else [
    sys.executable, "-m", "casadi_keyframe.cli"]
SMALL = ["flock_path", "--set", "agents=4", "--set", "steps=10"]
ROWS = []


def row(what, how, outcome, text):
    text = " ".join(text.split())
    first = text.replace("|", "\\|")[:230]
    ROWS.append((what, how, outcome, first, "Traceback" in text, "allow_pickle" in text))


def cli(what, *args):
    done = subprocess.run(COMMAND + [str(a) for a in args], capture_output=True, text=True,
                          timeout=600)
    text = done.stderr.strip() or (done.stdout.strip().splitlines() or [""])[-1]
    shown = "casadi-keyframe " + " ".join(str(a) for a in args)
    row(what, f"`{shown[:110]}`", f"exit {done.returncode}", text)


def cli_said(what, word, *args):
    """Like :func:`cli`, the line holding ``word`` (a note, a warning) as the message."""
    done = subprocess.run(COMMAND + [str(a) for a in args], capture_output=True, text=True,
                          timeout=600)
    lines = (done.stderr + "\n" + done.stdout).splitlines()
    said = next((line for line in lines if word in line), f"(no line with {word!r})")
    shown = "casadi-keyframe " + " ".join(str(a) for a in args)
    traceback = "Traceback" in done.stderr + done.stdout
    row(what, f"`{shown[:110]}`", f"exit {done.returncode}", said + (" Traceback" if traceback
                                                                      else ""))


def api(what, call: str, fn):
    try:
        fn()
        row(what, f"`{call}`", "no error", "")
    except Exception as err:  # noqa: BLE001 - the point is to show it
        row(what, f"`{call}`", type(err).__name__, str(err))


def npz_bytes(**arrays) -> bytes:
    buffer = io.BytesIO()
    np.savez(buffer, **{k: v for k, v in arrays.items() if v is not None})
    return buffer.getvalue()


def damaged(good: Path) -> dict:
    """name -> bytes of a damaged copy of the run file ``good``."""
    with np.load(good) as d:
        data = {k: d[k] for k in d.files}
    zipped = io.BytesIO()
    with zipfile.ZipFile(zipped, "w") as z:
        z.writestr("notes.txt", "hello")
    npy = io.BytesIO()
    np.save(npy, data["u"])
    raw = good.read_bytes()
    out = {
        "empty (0 bytes)": b"",
        "truncated (first half)": raw[: len(raw) // 2],
        "random bytes": bytes(np.random.default_rng(1).integers(0, 256, 5000, np.uint8)),
        "an .npy renamed": npy.getvalue(),
        "a zip of text": zipped.getvalue(),
        "pickled objects in u": npz_bytes(**{**data, "u": np.array([{"a": 1}], dtype=object)}),
        "no array u": npz_bytes(**{**data, "u": None}),
        "meta not JSON": npz_bytes(**{**data, "meta": np.array("{oops")}),
        "u as text": npz_bytes(**{**data, "u": np.array(["a", "b"])}),
    }
    if "x" in data:
        out["x one frame short"] = npz_bytes(**{**data, "x": data["x"][:-1],
                                                "v": data["v"][:-1]})
        out["history lengths differ"] = npz_bytes(
            **{**data, "history_seconds": np.r_[data["history_seconds"], 1.0]})
    return out


def solve_small(out: Path):
    subprocess.run(COMMAND + ["solve", *SMALL, "--maxiter", "2", "--out", str(out), "--quiet",
                              "--no-animation", "--no-viewer"], check=False,
                   capture_output=True)


def damaged_files(tmp: Path, run: Path):
    for name in ("result.npz", "checkpoint.npz"):
        for damage, content in damaged(run / name).items():
            folder = tmp / f"{name[:-4]}-{damage.replace(' ', '_')}"
            folder.mkdir()
            (folder / name).write_bytes(content)
            what = f"{name}: {damage}"
            if name == "result.npz":
                cli(what, "render", folder, "--no-animation")
                cli(what, "export", folder / name, "--format", "pc2")
            cli(what, "solve", *SMALL, "--out", tmp / "resumed", "--quiet", "--resume",
                folder / name)
    old = tmp / "old-result"
    old.mkdir()
    with np.load(run / "result.npz") as d:
        (old / "result.npz").write_bytes(npz_bytes(**{k: d[k] for k in d.files if k != "meta"}))
    (old / "summary.json").write_text('{"problem": "flock_path", "overr')
    cli("result.npz without meta, summary.json cut short", "render", old)
    cli("a folder with no run file", "render", tmp / "resumed-nothing-here")
    (tmp / "empty-folder").mkdir()
    cli("a folder with no run file", "export", tmp / "empty-folder", "--format", "obj")


def outputs(tmp: Path, run: Path):
    blocker = tmp / "a_file"
    blocker.write_text("")
    cli("export --out under a file", "export", run, "--format", "pc2", "--out", blocker / "x")
    cli("export --out in /proc", "export", run, "--format", "pc2", "--out", "/proc/nope")
    cli("export --out in /sys (read-only to files)", "export", run, "--format", "obj",
        "--out", "/sys/casadi_keyframe")
    cli("solve --out in /proc", "solve", *SMALL, "--out", "/proc/nope")
    cli("solve --out ''", "solve", *SMALL, "--out", "")
    cli("solve --out /dev/null (a file)", "solve", *SMALL, "--out", "/dev/null")
    cli("solve --out an existing file", "solve", *SMALL, "--out", blocker)
    cli("sweep --out under a file", "sweep", *SMALL, "--grid", "weight=1,2", "--out",
        blocker / "s")
    cli("study --grid --out under a file", "study", "gradient-accuracy", "--grid",
        "dt=1/30,1/60", "--out", blocker / "s")
    cli("study --out without --grid", "study", "gradient-accuracy", "--out", "")


PROBLEM_FILES = {
    "build() raises": '"""Raises."""\n\n\ndef build(k: int = 0):\n    return 1 / k\n',
    "import of a missing module": '"""No."""\nimport casadi_keyframe_nope\n',
    "NameError at import": '"""No."""\nX = undefined + 1\n',
    "syntax error": "def build(:\n",
    "no build()": "x = 1\n",
    "build() returns a number": '"""No."""\n\n\ndef build():\n    return 3\n',
    "build() gives the library bad shapes": (
        '"""Bad."""\nimport numpy as np\nfrom casadi_keyframe.objectives import '
        'CenterOfMassKeyframe\nfrom casadi_keyframe.scenes.flocks import blob, flock_problem\n'
        '\n\ndef build(agents: int = 4):\n    x0 = blob(agents + 1, (0, 0), 1.0, 2, '
        'np.random.default_rng(0))\n    return flock_problem(agents=agents, steps=10, dt=0.05, '
        'seed=0, dim=2, x0=x0, v0=np.zeros((agents, 2)),\n                         '
        'objective=CenterOfMassKeyframe(10, x=[1, 0]), name="bad")\n'),
    "an empty file": "",
    "null bytes": "\0\0\0garbage",
}


def problem_files(tmp: Path):
    for what, text in PROBLEM_FILES.items():
        path = tmp / f"p_{abs(hash(what)) % 10 ** 6}.py"
        path.write_text(text)
        cli(f"problem file: {what}", "solve", path, "--out", tmp / "pf")
    cli("problem file that does not exist", "show", tmp / "missing_problem.py")
    (tmp / "a_dir.py").mkdir()
    cli("problem file: a folder named .py", "solve", tmp / "a_dir.py")


def api_arguments(tmp: Path, run: Path):
    import casadi_keyframe as ck
    from casadi_keyframe.export import export

    prob = ck.load_problem("flock_path", agents=4, steps=10)
    n = prob.size
    for what, u in {"None": None, "complex": np.zeros(n, complex), "strings": ["a"] * n,
                    "booleans": np.zeros(n, bool), "Nones": [None] * n, "a dict": {"u": 1},
                    "ragged": [[1.0], [2.0, 3.0]], "too short": np.zeros(n - 1),
                    "a column": np.zeros((n, 1)), "NaN": np.full(n, np.nan)}.items():
        api(f"controls: {what}", f"prob.objective({what})", lambda u=u: prob.objective(u))
    api("controls: complex", "prob.objective_and_gradient(complex)",
        lambda: prob.objective_and_gradient(np.zeros(n, complex)))
    api("direction: complex", "prob.directional_derivative(u, complex)",
        lambda: prob.directional_derivative(np.zeros(n), np.zeros(n, complex)))
    api("controls: a string", "prob.breakdown('zeros')", lambda: prob.breakdown("zeros"))
    api("controls: None", "prob.control_cost(None)", lambda: prob.control_cost(None))
    for what, kwargs in {"maxiter=2.5": {"maxiter": 2.5}, "tol=-1": {"tol": -1},
                         "time_limit=0": {"time_limit": 0}, "method='bfgs'": {"method": "bfgs"},
                         "options={'maxitr': 5}": {"options": {"maxitr": 5}},
                         "ipopt options={'max_itr': 5}": {"method": "ipopt",
                                                         "options": {"max_itr": 5}},
                         "options=[1]": {"options": [1]}, "gradient='bad'": {"gradient": "bad"},
                         "u0=complex": {"u0": np.zeros(n, complex)},
                         "checkpoint=a folder": {"checkpoint": tmp},
                         "checkpoint under a file": {"checkpoint": tmp / "a_file" / "c.npz"},
                         "checkpoint in /proc": {"checkpoint": "/proc/nope/c.npz"},
                         "checkpoint=3": {"checkpoint": 3},
                         "continuation='x'": {"continuation": "x"},
                         "resolutions=3": {"resolutions": 3}}.items():
        api(f"solve: {what}", f"ck.solve(prob, {what})",
            lambda kwargs=kwargs: ck.solve(prob, quiet=True, **kwargs))
    api("export out under a file", "export(run, 'pc2', out=a_file/x)",
        lambda: export(run, "pc2", out=tmp / "a_file" / "x"))
    api("load_problem misspelt override", "ck.load_problem('flock_path', agnets=3)",
        lambda: ck.load_problem("flock_path", agnets=3))


def long_runs(tmp: Path):
    """The inputs issue 42 lists, each refused (exit 2) before any work, or run with the
    note or warning that says what was found."""
    import json
    import os

    import trimesh

    cape = ["cape_blend"]
    small = ["cape_blend", "--set", "rows=4", "--set", "cols=3"]
    out = ["--out", tmp / "long", "--quiet", "--no-animation", "--no-viewer"]
    for what, option in (("--finish bogus", "bogus"), ("--finish window=0", "effort,window=0"),
                         ("--finish maxiter=-1", "effort,maxiter=-1"),
                         ("--finish none with options", "none,window=3"),
                         ("--finish window given twice", "effort,window=3,window=4")):
        cli(what, "solve", *cape, "--finish", option, *out)
    (tmp / "garbage.obj").write_bytes(bytes(range(256)) * 8)
    (tmp / "empty.obj").write_bytes(b"")
    (tmp / "a_folder").mkdir(exist_ok=True)
    for what, body in (("cape body=cube (no such word)", "cube"),
                       ("cape body: a missing file", tmp / "missing.obj"),
                       ("cape body: garbage bytes", tmp / "garbage.obj"),
                       ("cape body: an empty file", tmp / "empty.obj"),
                       ("cape body: a folder", tmp / "a_folder")):
        cli(what, "solve", *cape, "--set", f"body={body}", *out)
    cli("mesh_keyframes bodies: a folder", "solve", "mesh_keyframes", "--set",
        f"bodies={tmp / 'a_folder'}", *out)
    ring = "".join(f"v {0.3 * np.cos(a):.6f} {0.3 * np.sin(a):.6f} 1.2\n"
                   for a in np.linspace(0, 2 * np.pi, 6)[:-1])
    (tmp / "pentagon.obj").write_text(ring + "f 1 2 3 4 5\n")
    cli_said("cape body: an open mesh (a flat pentagon)", "open:", "solve", *small, "--set",
             f"body={tmp / 'pentagon.obj'}", "--maxiter", "1", *out)
    box = trimesh.creation.box((0.4, 0.4, 0.6))
    box.apply_translation([0, 0, 1.1])
    faces = box.faces.copy()
    faces[[1, 6, 9]] = faces[[1, 6, 9]][:, ::-1]
    trimesh.Trimesh(box.vertices, faces, process=False).export(tmp / "mixed.obj")
    cli_said("cape body: a box with mixed winding", "wound against", "solve", *small,
             "--set", f"body={tmp / 'mixed.obj'}", "--maxiter", "1", *out)
    cli("a key given twice", "solve", *cape, "--set", "rows=4", "--set", "rows=5", *out)
    cli("an --option given twice", "solve", *cape, "--option", "maxcor=3", "--option",
        "maxcor=4", *out)
    cli("a --shooting key given twice", "solve", *cape, "--segments", "2", "--shooting",
        "workers=2", "--shooting", "workers=3", *out)
    shapes = ["cloth_shapes", "--set", "rows=4", "--set", "cols=4", "--set", "steps=12"]
    cli_said("a finish window longer than the run", "longer than", "solve", *shapes,
             "--finish", "effort,window=1000", "--maxiter", "1", *out)
    cli_said("a resolution no coarser than the problem", "not a coarser stage", "solve",
             *shapes, "--resolution", "rows=4,cols=4", "--maxiter", "1", *out)
    cli_said("a time limit the start does not fit in", "nothing written", "solve", *shapes,
             "--time-limit", "0.001", *out)
    cli_said("--draw-limit 0", "error:", "solve", *shapes, "--draw-limit", "0", *out)
    busy = tmp / "busy"
    busy.mkdir(exist_ok=True)
    (busy / ".casadi-keyframe.lock").write_text(json.dumps({"pid": os.getpid(),
                                                            "started": "now"}))
    cli("an --out folder in use by another run", "solve", *shapes, "--out", busy)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", help="folder for the runs and files (default: a temporary one)")
    args = ap.parse_args()
    tmp = Path(args.out or tempfile.mkdtemp(prefix="bad_inputs_"))
    tmp.mkdir(parents=True, exist_ok=True)
    run = tmp / "run"
    solve_small(run)
    damaged_files(tmp, run)
    outputs(tmp, run)
    problem_files(tmp)
    api_arguments(tmp, run)
    long_runs(tmp)
    print("| # | input | command or call | outcome | message | traceback | allow_pickle |")
    print("|---|---|---|---|---|---|---|")
    for i, (what, how, outcome, text, tb, pickle) in enumerate(ROWS, 1):
        print(f"| {i} | {what} | {how} | {outcome} | {text} | {'YES' if tb else 'no'} | "
              f"{'YES' if pickle else 'no'} |")
    bad = sum(r[4] or r[5] for r in ROWS)
    print(f"\n{len(ROWS)} inputs; {bad} with a traceback or allow_pickle advice")
    print(f"files in {tmp}")


if __name__ == "__main__":
    main()
