"""Pictures and exports of a fixed set of scenes, written to a folder to compare two revisions
byte by byte (what ``fingerprint.py`` is for trajectories and gradients).

    .venv/bin/python benchmarks/output_fingerprint.py --save /tmp/before   (on the old checkout)
    .venv/bin/python benchmarks/output_fingerprint.py --save /tmp/after    (on the new one)
    .venv/bin/python benchmarks/output_fingerprint.py --compare /tmp/before /tmp/after

A refactoring of render/ or export/ that should change no output is checked with it: every
file (snapshot and side-by-side PNGs, GIFs, USD as text, the HTML viewer with plotly's random
ids blanked, OBJ and PC2) is compared whole.  The scenes: a cloth touching a plane, a moving
sphere, a capsule and a turning mesh body, with whole-shape, particle, centre-of-mass and
velocity keyframes and a ring; flock_shapes (regions, 2-D) and flock_race; cape_blend (the
blend's clips); mesh_keyframes (exports only).
"""
import argparse
import re
import sys
from pathlib import Path

import numpy as np

UUID = re.compile(rb"[0-9a-f]{8}-[0-9a-f]{4}-[0-9a-f]{4}-[0-9a-f]{4}-[0-9a-f]{12}")


def octahedron():
    v = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1.0]]) * 0.15
    f = np.array([[0, 2, 4], [2, 1, 4], [1, 3, 4], [3, 0, 4], [2, 0, 5], [1, 2, 5], [3, 1, 5],
                  [0, 3, 5]])
    return v, f


def cloth_problem():
    from casadi_keyframe import (CenterOfMassKeyframe, ControlProblem, ParticleKeyframe,
                                 Smoothness, StateKeyframe, StepForces)
    from casadi_keyframe.integrators import LinearizedBackwardEuler
    from casadi_keyframe.models import Capsule, ClothModel, MeshBody, Plane, Sphere
    from casadi_keyframe.views import ClothView, Ring

    def spin(t):
        return (np.array([[np.cos(t), -np.sin(t), 0], [np.sin(t), np.cos(t), 0], [0, 0, 1.0]]),
                np.array([0.2, 0.8, -0.5 + 0.2 * t]))

    colliders = [Plane((0, 0, -1.0), (0, 0.1, 1)),
                 Sphere(lambda t: np.array([0.5, 0.2 - 0.3 * t, -0.7]), 0.2),
                 Capsule((0.1, 0.1, -0.9), (0.9, 0.1, -0.9), 0.05),
                 MeshBody(*octahedron(), motion=spin)]
    model = ClothModel.grid(5, 5, pinned=[0], colliders=colliders)
    x0, steps = model.rest_positions, 6
    obj = (StateKeyframe(steps, x=x0 + [0.0, 0.1, -0.2])
           + ParticleKeyframe(2, [3, 7], x=x0[[3, 7]] + [0, 0, -0.05])
           + CenterOfMassKeyframe(4, x=x0.mean(0) + [0, 0, -0.1])
           + StateKeyframe(5, v=np.zeros_like(x0)) + Smoothness(1e-4))
    return ControlProblem(model=model, integrator=LinearizedBackwardEuler(), x0=x0,
                          v0=np.zeros_like(x0), steps=steps, dt=1 / 30, controls=StepForces(),
                          objective=obj, name="outputs_cloth",
                          view=ClothView(camera=(25, -50),
                                         ring=Ring((0.5, 0.5, -0.3), (0, 0, 1), 0.2)))


def write(folder: Path, problem, pictures=True):
    from casadi_keyframe import render
    from casadi_keyframe.export import export_scene, scene_of
    from casadi_keyframe.export.usd import write_usd

    folder.mkdir(parents=True, exist_ok=True)
    u = problem.initial_controls() + 0.1 * np.random.default_rng(0).standard_normal(problem.size)
    traj = problem.simulate(u)
    if pictures:
        render.snapshot(problem, traj, folder / "snapshot.png")
        render.animate(problem, traj, folder / "animation.gif", max_frames=4)
    scene = scene_of(problem, traj)
    write_usd(scene, folder / "scene.usda")
    for fmt in ("html", "obj", "pc2"):
        export_scene(scene, fmt, folder)
    return traj


def save(out: Path):
    import casadi_keyframe as ck
    from casadi_keyframe.render import cloth

    prob = cloth_problem()
    traj = write(out / "cloth", prob)
    cloth.side_by_side(prob, {"a": traj, "b": traj}, out / "cloth" / "side.png")
    write(out / "flock_shapes", ck.load_problem("flock_shapes", agents=20, steps=30))
    write(out / "flock_race", ck.load_problem("flock_race"))
    write(out / "cape_blend", ck.load_problem("cape_blend", rows=6, cols=4, steps=4,
                                              guess="passive"))
    write(out / "mesh_keyframes", ck.load_problem("mesh_keyframes"), pictures=False)


def compare(a: Path, b: Path) -> int:
    files = sorted({p.relative_to(a) for p in a.rglob("*") if p.is_file()}
                   | {p.relative_to(b) for p in b.rglob("*") if p.is_file()})
    differ = 0
    for rel in files:
        if not ((a / rel).is_file() and (b / rel).is_file()):
            print(f"{rel}: only in {'after' if (b / rel).is_file() else 'before'}")
            differ += 1
            continue
        x, y = (a / rel).read_bytes(), (b / rel).read_bytes()
        if rel.suffix == ".html":
            x, y = UUID.sub(b"U", x), UUID.sub(b"U", y)
        if x != y:
            print(f"{rel}: differs")
            differ += 1
    print(f"{len(files) - differ} files identical, {differ} differ")
    return 0


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--save", metavar="DIR")
    ap.add_argument("--compare", nargs=2, metavar=("BEFORE", "AFTER"))
    args = ap.parse_args()
    if args.compare:
        return compare(*map(Path, args.compare))
    if not args.save:
        ap.error("give --save DIR or --compare BEFORE AFTER")
    save(Path(args.save))
    return 0


if __name__ == "__main__":
    sys.exit(main())
