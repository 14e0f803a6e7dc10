"""Sweeps on a local Dask cluster of two worker processes (loopback only): the same results
as solving each point alone, bit for bit; a worker killed with SIGKILL costs only its point's
time; Ctrl-C keeps the finished points and --resume solves only the others; bad input is
refused before any worker starts."""
import json
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

pytest.importorskip("distributed", reason="the sweep needs dask[distributed] (the test extra "
                                          "installs it)")

from casadi_keyframe.cli import main  # noqa: E402
from casadi_keyframe.cli.values import parse_grid  # noqa: E402
from casadi_keyframe.loading import load_module  # noqa: E402
from casadi_keyframe.runs import run_solve, solve_run  # noqa: E402
from casadi_keyframe.sweep import sweep  # noqa: E402
from casadi_keyframe.sweep.grid import folder_name, points, start_controls  # noqa: E402

SMALL = {"agents": 4, "steps": 20}
SETS = ["--set", "agents=4", "--set", "steps=20"]
# finite differences make a point last about a second: long enough to kill or interrupt
SLOW = ["--set", "agents=3", "--set", "steps=10", "--gradient", "fd", "--maxiter", "3",
        "--workers", "2"]


def test_grid_points_are_named_by_what_they_solve():
    pts = points({"weight": [1.0, 10.0], "cutoff": ["smooth", "hard"]}, starts=2)
    assert len(pts) == 8 and len({p.name for p in pts}) == 8
    assert pts[1].values == {"weight": 1.0, "cutoff": "smooth"} and pts[1].start == 1
    assert pts[1].name == "weight=1.0,cutoff=smooth,start=1"
    assert folder_name({"weight": 1.0}) == "weight=1.0"
    assert folder_name({"x": "a/b"}) != folder_name({"x": "a_b"})  # cleaned names get a hash
    with pytest.raises(ValueError, match="repeats"):
        points({"weight": [1.0, 1.0]})
    with pytest.raises(ValueError, match="no values"):
        points({"weight": []})


def test_perturbed_starts_are_seeded_and_start_zero_is_the_problems_own():
    prob = load_module("flock_path").build(**SMALL)
    assert start_controls(prob, 0) is None
    a, b = start_controls(prob, 1, seed=3), start_controls(prob, 1, seed=3)
    assert np.array_equal(a, b) and np.any(a != 0)
    assert not np.array_equal(a, start_controls(prob, 2, seed=3))


def test_parse_grid_splits_outside_brackets():
    assert parse_grid(["dt=1/30,1/60", "x=(0, 1),(2,3)", "c=smooth,hard"]) == {
        "dt": [1 / 30, 1 / 60], "x": [(0, 1), (2, 3)], "c": ["smooth", "hard"]}
    with pytest.raises(ValueError, match="twice"):
        parse_grid(["a=1", "a=2"])


def test_bad_input_is_refused_before_any_worker_starts(tmp_path, capsys):
    out = tmp_path / "s"
    assert main(["sweep", "flock_path", "--grid", "agentz=4,5", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "--grid agentz" in err and "did you mean agents" in err
    assert main(["sweep", "flock_path", "--grid", "agents=0,4", "--out", str(out)]) == 2
    assert "agents must be an integer in [1, inf)" in capsys.readouterr().err
    assert main(["sweep", "flock_path", "--grid", "agents=4", "--scheduler", "nonsense",
                 "--out", str(out)]) == 2
    assert "--scheduler nonsense: cannot reach a Dask scheduler" in capsys.readouterr().err
    with pytest.raises(ValueError, match="--workers sets the size of a local cluster"):
        sweep("flock_path", {"agents": [4]}, out=out, scheduler="tcp://127.0.0.1:9", workers=2)
    with pytest.raises(TypeError, match="unknown option.* maxiters"):
        sweep("flock_path", {"agents": [4]}, out=out, maxiters=3)
    with pytest.raises(ValueError, match="no workers|cannot reach"):
        sweep("flock_path", {"agents": [4]}, out=out, scheduler="tcp://127.0.0.1:9",
              timeout=1)
    assert not (out / "points").exists() or not any((out / "points").iterdir())


def test_a_sweep_equals_each_point_solved_alone_bit_for_bit(tmp_path, capsys):
    out = tmp_path / "sweep"
    result = sweep("flock_path", {"weight": [1.0, 10.0]}, starts=2, overrides=SMALL,
                   maxiter=4, out=out, workers=2, progress=False)
    assert result.exit_code == 0 and len(result.rows) == 4 and not result.failed
    assert len({r["worker"] for r in result.rows}) == 2  # both workers solved points
    table = (out / "sweep.csv").read_text().splitlines()
    assert len(table) == 5 and table[0].startswith("point,weight,start,status,objective")
    summary = json.loads((out / "sweep.json").read_text())
    assert {b["group"]["weight"] for b in summary["best"]} == {1.0, 10.0}  # best start each
    for row in result.rows:
        alone = tmp_path / f"alone-{row['point']}"
        if row["start"] == 0:  # the command a user would type
            code = main(["solve", "flock_path", *SETS, "--set", f"weight={row['weight']}",
                         "--maxiter", "4", "--out", str(alone), "--quiet", "--no-animation"])
        else:  # the same solve from the perturbed start
            alone.mkdir()
            spec = solve_run(load_module("flock_path"), "flock_path",
                             {**SMALL, "weight": row["weight"]}, alone,
                             given={"maxiter": 4}, quiet=True)
            spec.u0 = start_controls(spec.problem, row["start"])
            code = run_solve(spec)
        assert code == row["exit_code"] == 3  # stopped at --maxiter
        with np.load(alone / "result.npz") as a, np.load(f"{row['path']}/result.npz") as b:
            for key in ("u", "x", "v", "jac", "history_objective"):
                assert np.array_equal(a[key], b[key]), (row["point"], key)
    capsys.readouterr()


def start_sweep(out, *extra):
    cmd = [sys.executable, "-m", "casadi_keyframe.cli", "sweep", "flock_path",
           "--out", str(out), *SLOW, *extra]
    return subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)


def wait_until(condition, proc, what, timeout=60.0):
    end = time.monotonic() + timeout
    while not condition():
        if proc.poll() is not None or time.monotonic() > end:
            proc.kill()
            pytest.fail(f"{what} never happened:\n{proc.communicate()[0]}")
        time.sleep(0.05)


def rows(out):
    return {p.parent.name: json.loads(p.read_text()) for p in out.glob("points/*/row.json")}


def running_worker(out):
    """A point being solved now and the pid of its worker (the point's log names it, its
    row is not written yet), or None."""
    for log in out.glob("points/*/log.txt"):
        if not (log.parent / "row.json").exists():
            first = log.read_text().partition("\n")[0]
            if " on worker " in first:
                return log.parent, int(first.rsplit(":", 1)[1])
    return None


def test_a_worker_killed_mid_sweep_costs_only_its_point(tmp_path):
    out = tmp_path / "sweep"
    proc = start_sweep(out, "--grid", "weight=1,2,3,4")
    for _ in range(3):  # a point may finish between reading its log and the kill: next one
        wait_until(lambda: running_worker(out) is not None, proc, "a point starting")
        point, victim = running_worker(out)
        os.kill(victim, signal.SIGKILL)
        if not (point / "row.json").exists():  # killed mid-solve: its row never came
            break
    else:
        pytest.fail("no point was still running when its worker was killed")
    text = proc.communicate(timeout=120)[0]
    assert proc.returncode == 0, text
    assert (f"sweep: a worker died while solving {point.name}: Dask starts it again on "
            "another worker (start 2 of 3)") in text
    done = rows(out)
    assert len(done) == 4 and all(r["status"] != "error" for r in done.values()), text
    assert done[point.name]["worker"].rsplit(":", 1)[1] != str(victim)  # solved again
    assert len((out / "sweep.csv").read_text().splitlines()) == 5


def test_ctrl_c_keeps_finished_points_and_resume_solves_only_the_rest(tmp_path, capsys):
    out = tmp_path / "sweep"
    grid = ["--grid", "weight=1,2,3,4,5,6"]
    proc = start_sweep(out, *grid)
    wait_until(lambda: len(rows(out)) >= 1, proc, "a point finishing")
    proc.send_signal(signal.SIGINT)
    time.sleep(0.05)
    proc.send_signal(signal.SIGINT)  # impatient: a second Ctrl-C while the cluster closes
    text = proc.communicate(timeout=60)[0]
    assert proc.returncode == 130, text
    assert "Traceback" not in text and "leaked" not in text, text
    finished = rows(out)
    assert 1 <= len(finished) < 6, text
    assert "not run" in text and "--resume" in text
    stamps = {p: (out / "points" / p / "result.npz").stat().st_mtime_ns for p in finished}

    # without --resume the folder is refused
    assert main(["sweep", "flock_path", "--out", str(out), *SLOW, *grid]) == 2
    assert "give --resume" in capsys.readouterr().err
    resumed = start_sweep(out, *grid, "--resume")
    text = resumed.communicate(timeout=120)[0]
    assert resumed.returncode == 0, text
    assert f"{6 - len(finished)} point" in text
    assert f"to solve ({len(finished)} already complete, skipped)" in text
    assert {p: (out / "points" / p / "result.npz").stat().st_mtime_ns
            for p in finished} == stamps
    assert len(rows(out)) == 6 and len((out / "sweep.csv").read_text().splitlines()) == 7


def test_a_signal_after_every_point_finished_loses_nothing(tmp_path):
    """Exit 0 (not 130) when the points are all on disk, whenever the signal came."""
    from casadi_keyframe.sweep.plan import Plan, _finish

    specs = []
    for name in ("a", "b"):
        (tmp_path / name).mkdir()
        (tmp_path / name / "row.json").write_text(json.dumps(
            {"point": name, "k": 1, "status": "converged", "objective": 1.0, "spec_id": name,
             "path": str(tmp_path / name)}))
        specs.append({"folder": str(tmp_path / name), "id": name, "name": name})
    plan = Plan(specs, tmp_path, ["k"], "objective", [])
    assert _finish(plan, signal.SIGINT, 1.0, "local").exit_code == 0
    assert json.loads((tmp_path / "sweep.json").read_text())["signal_after_complete"] == "SIGINT"
    (tmp_path / "b" / "row.json").unlink()
    assert _finish(plan, signal.SIGINT, 1.0, "local").exit_code == 130


ROWS = [{"point": "a", "weight": 1.0, "start": 0, "status": "converged", "objective": 3.0,
         "path": "p/a"},
        {"point": "b", "weight": 1.0, "start": 1, "status": "converged", "objective": 2.0,
         "path": "p/b"},
        {"point": "c", "weight": 2.0, "start": 0, "status": "error", "reason": "KilledWorker",
         "path": "p/c"},
        {"point": "d", "weight": 2.0, "start": 1, "status": "limit reached",
         "objective": float("nan"), "path": "p/d", "x0": (1.0, 2.0)}]


def test_best_per_group_skips_failed_and_missing_figures():
    from casadi_keyframe.sweep.table import best_per_group

    assert best_per_group(ROWS, "objective", ["weight"]) == [
        {"group": {"weight": 1.0}, "point": "b", "objective": 2.0, "path": "p/b"}]
    assert [b["point"] for b in best_per_group(ROWS, "objective", [])] == ["b"]


def test_the_table_is_csv_and_parquet_with_the_same_rows(tmp_path):
    pq = pytest.importorskip("pyarrow.parquet", reason="Parquet needs the 'parquet' extra")
    from casadi_keyframe.sweep.table import write_tables

    files = write_tables(ROWS, tmp_path, ["weight"])
    assert [f.name for f in files] == ["sweep.csv", "sweep.parquet"]
    table = pq.read_table(tmp_path / "sweep.parquet").to_pylist()
    assert [r["point"] for r in table] == ["a", "b", "c", "d"]
    assert table[2]["reason"] == "KilledWorker" and table[3]["x0"] == "(1.0, 2.0)"
    header = (tmp_path / "sweep.csv").read_text().splitlines()[0]
    assert header == "point,weight,start,status,objective,reason,path,x0"


def test_a_study_grid_runs_through_the_same_runner(tmp_path, capsys):
    from casadi_keyframe.studies.accuracy import one_step_gap

    out = tmp_path / "study"
    assert main(["study", "integrator-accuracy", "--grid", "dt=1/30,1/60", "--out", str(out),
                 "--workers", "1", "--quiet"]) == 0
    got = {r["dt"]: r for r in rows(out).values()}
    expected = one_step_gap(dts=[1 / 30, 1 / 60])
    assert [got[dt]["gap_x"] for dt in expected["dt"]] == expected["gap_x"]
    assert [got[dt]["gap_v"] for dt in expected["dt"]] == expected["gap_v"]
    assert "best (all points): dt=0.016666666666666666" in capsys.readouterr().out


CURSED = '''"""A tiny flock whose build fails for k = 3."""
from casadi_keyframe.scenes.flock_path import flock_path_problem

RANGES = {"k": "[0, 10]"}


def build(k: int = 0):
    if k == 3:
        raise ValueError("k = 3 is cursed")
    return flock_path_problem(agents=3, steps=10)
'''


def test_a_failing_point_is_a_row_with_its_reason(tmp_path):
    from casadi_keyframe.sweep.runner import _row_of
    from casadi_keyframe.sweep.tasks import read_row, run_task

    path = tmp_path / "cursed.py"
    path.write_text(CURSED)
    spec = {"kind": "solve", "problem_file": str(path), "problem_arg": str(path),
            "overrides": {"k": 3}, "options": {"maxiter": 2}, "values": {"k": 3},
            "name": "k=3", "label": "k=3", "folder": str(tmp_path / "k=3"), "id": "x"}
    row = run_task(spec)
    assert row["status"] == "error" and row["reason"] == (
        f"problem file {path} failed in build() at line 9 (raise ValueError(\"k = 3 is "
        f"cursed\")): ValueError: k = 3 is cursed")
    assert read_row(tmp_path / "k=3") == row

    class KilledWorker(Exception):
        pass

    class Lost:  # a future Dask gave up on: every worker running it died
        status = "error"

        def exception(self):
            return KilledWorker("attempted to run task point-y on 3 different workers")

    lost = _row_of(Lost(), {**spec, "name": "k=4", "values": {"k": 4},
                            "folder": str(tmp_path / "k=4"), "id": "y"})
    assert lost["status"] == "error" and "died" in lost["reason"] and lost["k"] == 4
    assert read_row(tmp_path / "k=4")["reason"] == lost["reason"]


def test_the_watch_names_a_dead_workers_points_from_outside():
    """A scheduler that cannot run the library (a remote cluster without it) is watched by
    its workers and what each was running."""
    from casadi_keyframe.sweep.watch import WorkerWatch

    class Remote:
        def __init__(self):
            self.workers, self.processing_now = {"a": 1, "b": 1}, {"a": ["k1"], "b": ["k2"]}

        def run_on_scheduler(self, *args):
            raise ModuleNotFoundError("No module named 'casadi_keyframe'")

        def nthreads(self):
            return self.workers

        def processing(self):
            return self.processing_now

    said, client = [], Remote()
    watch = WorkerWatch(said.append, tries=2)
    labels = {"k1": "weight=1", "k2": "weight=2"}
    watch.poll(client, labels)
    client.workers, client.processing_now = {"b": 1, "c": 1}, {"b": ["k2"], "c": ["k1"]}
    watch.poll(client, labels)
    assert said == ["sweep: a worker died while solving weight=1: Dask starts it again on "
                    "another worker (start 2 of 2)"]
    client.workers = {"b": 1}
    watch.poll(client, labels)
    assert said[-1].endswith("that was its last of 2 starts (--tries): it is reported failed")
