"""Long runs as a user meets them on a terminal: how long each stays silent, how soon it
stops after the first Ctrl-C or SIGTERM in each stage, its wall time against
``--time-limit``, and how soon a bad option is refused.  Prints a Markdown table.

Each command runs in its own process on a pseudo-terminal (so it prints as it would to a
user: progress bars, line buffering); every chunk it prints is timed.  A signal is sent
``after`` seconds past the first output line matching ``when`` (or past the start).

    .venv/bin/python benchmarks/long_runs.py [--only NAME,...] [--code CHECKOUT] [--list]

``--code`` runs another checkout's package (its root on PYTHONPATH: the revision before a
change); the default is this one.  Runs take minutes each on a 2-core machine.
"""
from __future__ import annotations

import argparse
import fcntl
import os
import pty
import re
import select
import signal
import struct
import subprocess
import sys
import tempfile
import termios
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
CAPE = ["cape_blend", "--set", "rows=8", "--set", "cols=6"]
SHAPES5 = ["cloth_shapes", "--set", "rows=5", "--set", "cols=5"]


def runs(tmp: Path, code: Path) -> list[dict]:
    """The runs: ``name``, ``args`` (after ``casadi-keyframe``), ``signal`` and ``after``
    (seconds past the line matching ``when``; None: past the start), ``limit`` (the
    --time-limit given), ``holder`` (a run started first into the same folder)."""
    solve = lambda *a: ["solve", *a, "--out", str(tmp / "out"), "--no-viewer"]  # noqa: E731
    mesh = ["mesh_keyframes", "--set", f"bodies={tmp / 'ball.obj'}"]
    passive = [*CAPE, "--set", "guess=passive"]
    return [
        # the stages, each sent a first signal while it works
        dict(name="search: SIGINT", args=solve(*passive, "--segments", "1", "--finish",
                                               "none"),
             signal=signal.SIGINT, when="start", after=15),
        dict(name="finish: SIGINT", args=solve(*CAPE), signal=signal.SIGINT, when="start",
             after=25),
        dict(name="finish: SIGTERM", args=solve(*CAPE), signal=signal.SIGTERM, when="start",
             after=25),
        dict(name="shooting workers=2: SIGINT", args=solve(*passive, "--shooting", "workers=2"),
             signal=signal.SIGINT, when="start", after=25),
        dict(name="homotopy level: SIGINT",
             args=solve(*passive, "--segments", "1", "--homotopy", "contact=3"),
             signal=signal.SIGINT, when="start", after=15),
        dict(name="homotopy level: SIGTERM",
             args=solve(*passive, "--segments", "1", "--homotopy", "contact=3"),
             signal=signal.SIGTERM, when="start", after=15),
        dict(name="first evaluation (fd gradient): SIGINT",
             args=solve("flock_path", "--set", "agents=8", "--gradient", "fd"),
             signal=signal.SIGINT, when="start", after=5),
        dict(name="start simulation, 3000 steps: SIGINT",
             args=solve("cloth_shapes", "--set", "rows=12", "--set", "cols=12", "--set",
                        "steps=3000", "--resolution", "none"),
             signal=signal.SIGINT, when=None, after=20),
        dict(name="drawing flock_shapes: SIGINT", args=solve("flock_shapes"),
             signal=signal.SIGINT, when="result written", after=3),
        # time limits
        dict(name="cloth_shapes 5x5 finish window=1000, limit 15 s",
             args=solve(*SHAPES5, "--finish", "effort,window=1000", "--maxiter", "2",
                        "--time-limit", "15", "--no-animation"), limit=15),
        dict(name="mesh_keyframes + mesh body, limit 40 s",
             args=solve(*mesh, "--time-limit", "40", "--no-animation"), limit=40),
        dict(name="cape 8x6 passive shooting workers=2, limit 40 s",
             args=solve(*passive, "--shooting", "workers=2", "--time-limit", "40",
                        "--no-animation"), limit=40),
        dict(name="cape 8x6 homotopy contact=3, limit 40 s",
             args=solve(*CAPE, "--homotopy", "contact=3", "--time-limit", "40",
                        "--no-animation"), limit=40),
        dict(name="cape 8x6 passive homotopy contact=3, limit 40 s",
             args=solve(*passive, "--segments", "1", "--homotopy", "contact=3",
                        "--time-limit", "40", "--no-animation"), limit=40),
        # silence, drawing included
        dict(name="flock_path (pictures)", args=solve("flock_path")),
        dict(name="flock_shapes (pictures)", args=solve("flock_shapes")),
        dict(name="cape 4x3 homotopy contact=3",
             args=solve("cape_blend", "--set", "rows=4", "--set", "cols=3", "--homotopy",
                        "contact=3")),
        dict(name="make demo", args=demo(code, tmp)),
        # bad options: seconds until refused
        dict(name="refused: --finish bogus", args=solve("cape_blend", "--finish", "bogus")),
        dict(name="refused: --finish effort,window=0",
             args=solve("cape_blend", "--finish", "effort,window=0")),
        dict(name="refused: --finish effort,maxiter=-1",
             args=solve("cape_blend", "--finish", "effort,maxiter=-1")),
        dict(name="refused: --finish none,window=3",
             args=solve("cape_blend", "--finish", "none,window=3")),
        dict(name="refused: --set rows=4 --set rows=5",
             args=solve("cape_blend", "--set", "rows=4", "--set", "rows=5")),
        dict(name="refused: body=cube", args=solve("cape_blend", "--set", "body=cube")),
        dict(name="refused: a missing body file",
             args=solve("cape_blend", "--set", f"body={tmp / 'missing.obj'}")),
        dict(name="refused: a garbage body file",
             args=solve("cape_blend", "--set", f"body={tmp / 'garbage.obj'}")),
        dict(name="refused: an empty body file",
             args=solve("cape_blend", "--set", f"body={tmp / 'empty.obj'}")),
        dict(name="refused: a folder as the body",
             args=solve("cape_blend", "--set", f"body={tmp}")),
        dict(name="refused: a folder in use", args=solve("flock_path", "--set", "agents=4"),
             holder=solve("flock_path", "--gradient", "fd")),
        dict(name="open mesh body (a flat pentagon)",
             args=solve(*CAPE, "--set", f"body={tmp / 'pentagon.obj'}", "--time-limit", "90")),
        dict(name="box of quads with mixed winding",
             args=solve(*CAPE, "--set", f"body={tmp / 'mixed_box.obj'}", "--time-limit", "90")),
    ]


def demo(code: Path, tmp: Path) -> list[str]:
    """``make demo``'s command as that checkout's Makefile writes it, into ``tmp``."""
    for line in (code / "Makefile").read_text().splitlines():
        if "casadi-keyframe solve" in line:
            words = line.split("casadi-keyframe", 1)[1].split()
            at = words.index("--out")
            return words[:at] + ["--out", str(tmp / "demo")] + words[at + 2:]
    raise SystemExit(f"{code}/Makefile has no demo target")


def write_bodies(tmp: Path) -> None:
    """The body files the runs read: a ball in mesh_keyframes' sheet's way, bytes that are
    no mesh, an empty file, a flat pentagon (open) and a box of quads with two faces wound
    the other way."""
    import numpy as np
    import trimesh

    ball = trimesh.creation.icosphere(subdivisions=3, radius=0.2)
    ball.apply_translation([0.5, 0.3, -0.6])  # where mesh_keyframes' sheet folds into it
    ball.export(tmp / "ball.obj")
    (tmp / "empty.obj").write_bytes(b"")
    (tmp / "garbage.obj").write_bytes(bytes(np.random.default_rng(0).integers(0, 256, 4000,
                                                                             np.uint8)))
    angles = np.linspace(0, 2 * np.pi, 6)[:-1]
    ring = "".join(f"v {0.3 * np.cos(a):.6f} {0.3 * np.sin(a):.6f} 1.2\n" for a in angles)
    (tmp / "pentagon.obj").write_text(ring + "f 1 2 3 4 5\n")
    corners = "".join(f"v {x} {y} {z}\n" for z in (0.8, 1.4) for y in (-0.2, 0.2)
                      for x in (-0.2, 0.2))
    quads = ["1 3 4 2", "5 6 8 7", "1 2 6 5", "3 7 8 4", "1 5 7 3", "2 4 8 6"]
    quads[1], quads[3] = "5 7 8 6", "3 4 8 7"  # two faces wound the other way
    (tmp / "mixed_box.obj").write_text(corners + "".join(f"f {q}\n" for q in quads))


def run(case: dict, code: Path, tmp: Path, timeout: float = 1200) -> dict:
    """Run ``case`` on a pseudo-terminal (after its ``holder``, if any, has started); its
    wall time, exit code (None: killed at ``timeout`` s), longest silence, when the signal
    was sent and the seconds from it to the exit, and its last lines."""
    env = {**os.environ, "PYTHONPATH": str(code), "OMP_NUM_THREADS": "1",
           "COLUMNS": "120", "LINES": "40"}
    holder = None
    if case.get("holder"):
        holder = subprocess.Popen([sys.executable, "-m", "casadi_keyframe.cli",
                                   *case["holder"]], stdout=subprocess.DEVNULL,
                                  stderr=subprocess.DEVNULL, env=env, cwd=tmp,
                                  start_new_session=True)
        time.sleep(8)  # it has taken the folder
    master, slave = pty.openpty()
    fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", 40, 120, 0, 0))  # a terminal's
    started = time.monotonic()
    proc = subprocess.Popen([sys.executable, "-m", "casadi_keyframe.cli", *case["args"]],
                            stdin=subprocess.DEVNULL, stdout=slave, stderr=slave, env=env,
                            cwd=tmp, start_new_session=True, preexec_fn=_as_a_user)
    os.close(slave)
    text, last, silence, sent, seen, written = b"", started, 0.0, None, None, None
    when, after = case.get("when", "never"), case.get("after")
    while True:
        ready, _, _ = select.select([master], [], [], 0.2)
        now = time.monotonic()
        if ready:
            try:
                chunk = os.read(master, 65536)
            except OSError:
                chunk = b""
            if not chunk:
                break
            text += chunk
            silence, last = max(silence, now - last), now
            said = text.decode("utf8", "replace")
            if seen is None and when and re.search(_pattern(when), said):
                seen = now
            if written is None and ("result written" in said or "nothing written" in said):
                written = now
        if case.get("signal") and sent is None:
            base = started if when is None else seen
            if base is not None and now - base >= after:
                proc.send_signal(case["signal"])
                sent = now
        if proc.poll() is not None and not ready:
            break
        if now - started > timeout:
            os.killpg(proc.pid, signal.SIGKILL)
    proc.wait()
    if holder is not None:
        os.killpg(holder.pid, signal.SIGKILL)
        holder.wait()
    ended = time.monotonic()
    silence = max(silence, ended - last)
    os.close(master)
    said = re.sub(r"\x1b\[K", "", text.decode("utf8", "replace"))
    lines = [s.strip() for s in re.split(r"[\r\n]+", said) if s.strip()]
    killed = proc.returncode == -signal.SIGKILL
    return {"wall": ended - started, "written": None if written is None else written - started,
            "code": None if killed else proc.returncode,
            "silence": silence,
            "stop": None if sent is None else ended - sent, "last": lines[-3:] if lines else [],
            "lines": lines}


def _as_a_user() -> None:
    """In the child: Ctrl-C acts as in a terminal's foreground job, even when this script
    runs in the background (where a shell ignores SIGINT for it and its children)."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def _pattern(when: str) -> str:
    return {"start": r"controls; start \("}.get(when, re.escape(when))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", help="comma-separated start of run names to run")
    ap.add_argument("--code", default=str(ROOT), help="checkout whose package runs")
    ap.add_argument("--list", action="store_true", help="list the runs")
    ap.add_argument("--log", help="file to append each run's whole output to")
    ap.add_argument("--timeout", type=float, default=1200,
                    help="seconds after which a run is killed (default 1200)")
    args = ap.parse_args(argv)
    tmp = Path(tempfile.mkdtemp(prefix="long_runs_"))
    write_bodies(tmp)
    chosen = runs(tmp, Path(args.code))
    if args.list:
        print("\n".join(c["name"] for c in chosen))
        return 0
    if args.only:
        wanted = [w.strip() for w in args.only.split(",")]
        chosen = [c for c in chosen if any(c["name"].startswith(w) for w in wanted)]
    print("| run | exit | wall s | result written at s | limit s | first signal -> exit s | "
          "longest silence s | last line |")
    print("|---|---|---|---|---|---|---|---|")
    for case in chosen:
        got = run(case, Path(args.code), tmp, args.timeout)
        if args.log:
            with open(args.log, "a") as log:
                log.write(f"\n===== {case['name']}: {' '.join(case['args'])}\n"
                          + "\n".join(got["lines"]) + "\n")
        stop = "" if got["stop"] is None else f"{got['stop']:.1f}"
        last = (got["last"][-1] if got["last"] else "").replace("|", "\\|")[:160]
        code = "killed" if got["code"] is None else got["code"]
        written = "" if got["written"] is None else f"{got['written']:.1f}"
        print(f"| {case['name']} | {code} | {got['wall']:.1f} | {written} | "
              f"{case.get('limit', '')} | {stop} | {got['silence']:.1f} | {last} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
