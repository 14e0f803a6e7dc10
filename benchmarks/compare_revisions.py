"""Run one benchmark script on two checkouts of the repository, interleaved, and compare.

    .venv/bin/python benchmarks/compare_revisions.py --before /work/before --after . --rounds 5 \\
        -- benchmarks/flock_gradient.py --agents 200 1000 --steps 100 --repeats 3
    .venv/bin/python benchmarks/compare_revisions.py --rev a7475cf --rounds 5 \\
        -- benchmarks/cloth_gradient.py --sizes 10 20 --steps 50

``--rev REV`` instead of ``--before DIR`` makes a temporary ``git worktree`` of REV (from the
``--after`` checkout's repository) and removes it afterwards.  Everything after ``--`` is the
benchmark script, relative to each checkout, and its arguments.

Each round runs the script once in each checkout, alternating which goes first.  Every run is
a fresh subprocess of this interpreter (``sys.executable``) with ``cwd`` = the checkout,
``PYTHONPATH`` = the checkout (so each side imports its own ``casadi_keyframe``; the driver
prints the package file each side imported and stops if it is not inside that checkout), one
BLAS/OpenMP thread, and one kernel cache shared by both sides (``CASADI_KEYFRAME_CACHE``:
``--cache``, else the variable's value, else a temporary folder removed afterwards).  Kernels
are named by their content, so sharing is safe and a kernel is compiled at most once.

The script's table is parsed generically: a row is a line whose first tokens are a key (the
size, and any words after it such as a solver's name) and whose other tokens are numbers or
placeholders such as ``-``; the header is the
last other line before the first row.  Numeric columns are taken by position; a column is
named by the header text above it when the two line up character by character, else only by
its index.  The output lists, per row and numeric column, the median over rounds before and
after, their ratio after/before, and the smallest and largest of the per-round ratios
(round r's after / round r's before).  For times, a ratio below 1 means the after checkout
is faster; a difference is above noise only when the per-round ratios all lie on the same
side of 1.  Columns equal in every run on both sides are listed once, not compared.  The
pseudo-row ``(run)`` gives each whole subprocess's CPU seconds (user + system, children
included) and wall seconds; round 1 may include kernel compilation and imports are in it.

The scripts time themselves (``benchmarks/timing.py``: best of a few wall-time calls); the
interleaving and the medians are this driver's control of the machine's noise.
"""
import argparse
import os
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

MARK = "@@compare_revisions imported:"
# Run the script as ``python script`` would (script folder first on sys.path, not the cwd),
# then report which casadi_keyframe it imported, even if it exits with an error.
BOOT = ("import os, runpy, sys\n"
        "s = sys.argv[1]; sys.argv = sys.argv[1:]; sys.path[0] = os.path.dirname(os.path.abspath(s))\n"
        "try:\n    runpy.run_path(s, run_name='__main__')\n"
        "finally:\n    m = sys.modules.get('casadi_keyframe')\n"
        f"    print({MARK!r}, getattr(m, '__file__', None), file=sys.stderr)\n")


def number(tok: str):
    try:
        return float(tok)
    except ValueError:
        return None


def key_length(toks: list[str]) -> int:
    """How many leading tokens name a row: the first and any words after it ("50x50 auto")."""
    k = 1
    while k < len(toks) and number(toks[k]) is None and any(c.isalnum() for c in toks[k]):
        k += 1
    return k


def is_row(toks: list[str]) -> bool:
    """A key (one or more words) followed by numbers and placeholders (tokens with no letter
    or digit)."""
    rest = toks[key_length(toks):]
    return (len(rest) >= 1 and any(number(t) is not None for t in rest)
            and all(number(t) is not None or not any(c.isalnum() for c in t) for t in rest))


def spans(line: str) -> list[tuple[int, int]]:
    """(start, end) of each whitespace-separated token."""
    out, i = [], 0
    for tok in line.split():
        i = line.index(tok, i)
        out.append((i, i + len(tok)))
        i += len(tok)
    return out


def column_names(header: str, row: str) -> list[str]:
    """Header text above each of ``row``'s tokens: from the previous token's end to this
    token's end (right-aligned columns), kept only where it does not cut a header word."""
    names, prev = [], 0
    for start, end in spans(row):
        cut_end = end < len(header) and not header[end].isspace() and not header[end - 1].isspace()
        cut_start = (0 < prev < len(header) and not header[prev].isspace()
                     and not header[prev - 1].isspace())
        text = header[prev:end].strip()
        names.append("" if cut_end or cut_start else text)
        prev = end
    return names


def parse(stdout: str) -> tuple[dict[str, list], list[str]]:
    """{key: [float or None per token position]}, and column names by position."""
    rows, names, header = {}, [], ""
    for line in stdout.splitlines():
        toks = line.split()
        if not toks:
            continue
        if not is_row(toks):
            if not rows:
                header = line
            continue
        if not names:
            names = column_names(header, line)
        rows[" ".join(toks[:key_length(toks)])] = [number(t) for t in toks]
    return rows, names


def run(label: str, checkout: Path, script: list[str], cache: str) -> dict:
    env = {**os.environ, "PYTHONPATH": str(checkout), "CASADI_KEYFRAME_CACHE": cache,
           "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t = time.perf_counter()
    p = subprocess.run([sys.executable, "-c", BOOT, *script], cwd=checkout, env=env,
                       capture_output=True, text=True)
    wall = time.perf_counter() - t
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    imported = [ln[len(MARK):].strip() for ln in p.stderr.splitlines() if ln.startswith(MARK)]
    if p.returncode:
        err = "\n".join(ln for ln in p.stderr.splitlines() if not ln.startswith(MARK))
        sys.exit(f"{label} ({checkout}) failed with exit code {p.returncode}:\n"
                 f"{p.stdout[-3000:]}\n{err[-6000:]}")
    rows, names = parse(p.stdout)
    if not rows:
        sys.exit(f"{label}: no table rows found in the output:\n{p.stdout}")
    return {"rows": rows, "names": names, "cpu": cpu, "wall": wall, "stdout": p.stdout,
            "imported": imported[0] if imported and imported[0] != "None" else None}


def fmt(x: float) -> str:
    return f"{x:.4g}"


def report(runs: dict[str, list[dict]]) -> None:
    before, after = runs["before"], runs["after"]
    names = before[0]["names"] or after[0]["names"]
    keys = [k for k in before[0]["rows"] if all(k in r["rows"] for r in before + after)]
    missing = set().union(*(r["rows"] for r in before + after)) - set(keys)
    if missing:
        print(f"rows not in every run, skipped: {' '.join(sorted(missing))}")
    print(f"{'row':>8} {'column':<26} {'before':>10} {'after':>10} {'after/before':>12} "
          f"{'per-round min':>13} {'max':>7}")
    constant = []
    for key in keys:
        width = max(len(r["rows"][key]) for r in before + after)
        for j in range(1, width):
            b = [r["rows"][key][j] if j < len(r["rows"][key]) else None for r in before]
            a = [r["rows"][key][j] if j < len(r["rows"][key]) else None for r in after]
            if None in a + b:
                continue  # a placeholder or a missing column in some run
            name = f"[{j}] {names[j]}" if j < len(names) and names[j] else f"[{j}]"
            if len(set(a + b)) == 1:
                constant.append(f"{key} {name} = {fmt(a[0])}")
                continue
            compare(key, name, b, a)
    compare("(run)", "cpu s", [r["cpu"] for r in before], [r["cpu"] for r in after])
    compare("(run)", "wall s", [r["wall"] for r in before], [r["wall"] for r in after])
    if constant:
        print("equal in every run: " + "; ".join(constant))


def compare(key: str, name: str, b: list[float], a: list[float]) -> None:
    mb, ma = statistics.median(b), statistics.median(a)
    per = [y / x for x, y in zip(b, a) if x]
    ratio = fmt(ma / mb) if mb else "-"
    lo, hi = (fmt(min(per)), fmt(max(per))) if per else ("-", "-")
    print(f"{key:>8} {name:<26} {fmt(mb):>10} {fmt(ma):>10} {ratio:>12} {lo:>13} {hi:>7}")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0],
                                 usage="%(prog)s (--before DIR | --rev REV) [--after DIR] "
                                       "[--rounds N] [--cache DIR] [-v] -- SCRIPT [ARGS ...]")
    side = ap.add_mutually_exclusive_group(required=True)
    side.add_argument("--before", type=Path, help="checkout of the old code")
    side.add_argument("--rev", help="git revision; a temporary worktree of it is the old code")
    ap.add_argument("--after", type=Path, default=Path("."), help="checkout of the new code")
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--cache", help="kernel cache shared by both sides")
    ap.add_argument("-v", "--verbose", action="store_true", help="print every run's output")
    ap.add_argument("script", nargs=argparse.REMAINDER, help="-- SCRIPT [ARGS ...]")
    args = ap.parse_args()
    script = args.script[1:] if args.script[:1] == ["--"] else args.script
    if not script:
        ap.error("give the benchmark script after --")
    after = args.after.resolve()
    tmp = Path(tempfile.mkdtemp(prefix="compare_revisions_"))
    cache = args.cache or os.environ.get("CASADI_KEYFRAME_CACHE") or str(tmp / "cache")
    worktree = None
    try:
        if args.rev:
            worktree = tmp / "before"
            subprocess.run(["git", "-C", str(after), "worktree", "add", "--detach", "--quiet",
                            str(worktree), args.rev], check=True)
        checkouts = {"before": worktree or args.before.resolve(), "after": after}
        for label, where in checkouts.items():
            if not (where / script[0]).is_file():
                sys.exit(f"{label}: no {script[0]} in {where}")
        print(f"before: {checkouts['before']} ({describe(checkouts['before'])})")
        print(f"after:  {after} ({describe(after)})")
        print(f"script: {' '.join(script)}; {args.rounds} rounds, kernel cache {cache}")
        runs = {"before": [], "after": []}
        for r in range(args.rounds):
            order = ["before", "after"] if r % 2 == 0 else ["after", "before"]
            for label in order:
                res = run(label, checkouts[label], script, cache)
                if not runs[label]:
                    print(f"{label} imported {res['imported']}")
                    if res["imported"] is None:  # the script imports it in its own children
                        print(f"{label}: the script itself imported no casadi_keyframe; its "
                              "subprocesses inherit PYTHONPATH = the checkout")
                    elif not res["imported"].startswith(str(checkouts[label]) + os.sep):
                        sys.exit(f"{label} did not import casadi_keyframe from its checkout")
                elif res["imported"] != runs[label][0]["imported"]:
                    sys.exit(f"{label} imported {res['imported']} in round {r + 1}")
                runs[label].append(res)
                print(f"round {r + 1}/{args.rounds} {label:6}: {res['cpu']:.1f} s CPU, "
                      f"{res['wall']:.1f} s wall", file=sys.stderr, flush=True)
                if args.verbose:
                    print(res["stdout"], file=sys.stderr)
        report(runs)
    finally:
        if worktree is not None:
            subprocess.run(["git", "-C", str(after), "worktree", "remove", "--force",
                            str(worktree)], check=False)
        shutil.rmtree(tmp, ignore_errors=True)


def describe(checkout: Path) -> str:
    """Commit and whether the tree has uncommitted changes."""
    git = ["git", "-C", str(checkout)]
    head = subprocess.run(git + ["rev-parse", "--short", "HEAD"], capture_output=True,
                          text=True).stdout.strip() or "not a git checkout"
    dirty = subprocess.run(git + ["status", "--porcelain", "--untracked-files=no"],
                           capture_output=True, text=True).stdout.strip()
    return head + (" + uncommitted changes" if dirty else "")


if __name__ == "__main__":
    main()
