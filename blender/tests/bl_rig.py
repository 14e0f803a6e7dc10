"""Run by a Blender Python (``python bl_rig.py -- JOB.json OUT.json``), not by pytest: the
rigged example (``blender/rigged_cape.py``) built, the add-on installed from its zip and
Solve pressed headless on the cape (with ``cancel_after``: the add-on's solve process
started and cancelled as Esc does after that many seconds of search, its best point
loaded); with ``resolve_from``, a target pose then added later in the shot
(``resolve_target``: frame and flare) and "Re-solve from Current Frame" pressed at that
frame (with the Solver options ``resolve_options``).  What Blender then shows is dumped per frame: the cape
through its Mesh Cache in world space, how far its pinned vertices are from where the rig
puts them, how deep any cape vertex is inside the evaluated character, and the cape against
its target shape key at the keyframe."""
import json
import sys
import time
from pathlib import Path

import bpy
import addon_utils  # noqa: E402 (importable once bpy is)
from mathutils import Vector
from mathutils.bvhtree import BVHTree

job_path, out_path = sys.argv[sys.argv.index("--") + 1:][:2]
job = json.loads(open(job_path).read())
bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.ops.preferences.addon_install(filepath=job["addon"], overwrite=True)
addon_utils.enable("casadi_keyframe_blender", default_set=True)
bpy.context.preferences.addons["casadi_keyframe_blender"].preferences.executable = \
    job["executable"]
from casadi_keyframe_blender import collect, solving  # noqa: E402 (once enabled)

sys.path.insert(0, job["rig"])
import rigged_cape  # noqa: E402

objects = rigged_cape.build(**job["build"])
cape, character = objects["cape"], objects["character"]
scene = bpy.context.scene
settings = scene.casadi_keyframe
settings.tolerance, settings.maxiter, settings.folder = (job["tolerance"], job["maxiter"],
                                                         job["folder"])
settings.options = job.get("options", "")


def solve_and_cancel(after: float) -> dict:
    """The add-on's solve as the modal operator runs it, Esc (``cancel``) after ``after``
    seconds of search; the best point loaded."""
    command, out = collect.prepare(bpy.context, job["executable"])
    run = solving.SolveProcess(command)
    began = None
    while run.running and (began is None or time.monotonic() - began < after):
        for line in run.drain(wait=0.2):
            print("casadi-keyframe:", line)
            if began is None and "iterations" in line:
                began = time.monotonic()  # the search has started
    asked = time.monotonic()
    run.cancel()
    code = run.wait()
    stopped = time.monotonic() - asked
    lines = solving.finish(bpy.context, cape, out, code)
    return {"code": code, "stop_seconds": stopped, "misses": "; ".join(lines),
            "status": run.status()}


def world_mesh(obj, depsgraph):
    ev = obj.evaluated_get(depsgraph)
    mesh = ev.to_mesh()
    points = [ev.matrix_world @ v.co for v in mesh.vertices]
    faces = [list(p.vertices) for p in mesh.polygons]
    ev.to_mesh_clear()
    return points, faces


def inside(bvh, point) -> bool:
    """Whether ``point`` is inside the closed mesh of ``bvh``: odd crossings along +z."""
    crossings, origin, up = 0, point.copy(), point.copy()
    up.x, up.y, up.z = 0.0, 0.0, 1.0
    while True:
        hit = bvh.ray_cast(origin, up)
        if hit[0] is None:
            return crossings % 2 == 1
        crossings += 1
        origin = hit[0] + up * 1e-7


def measure(frames: int) -> dict:
    """Per frame from the scene's start: the cape (world), its pins' distance to the rig's
    pins, the deepest cape vertex inside the character."""
    pins = collect.pinned(cape, "pins")
    spine = objects["rig"].pose.bones["spine"]
    seen = {"cloth": [], "pin_error": [], "depth": [], "gap": [], "pin_route": []}
    for k in range(frames):
        scene.frame_set(scene.frame_start + k)
        depsgraph = bpy.context.evaluated_depsgraph_get()
        cloth, _ = world_mesh(cape, depsgraph)
        body, faces = world_mesh(character, depsgraph)
        bvh = BVHTree.FromPolygons(body, faces)
        with collect.shaped(cape):
            rig, _ = world_mesh(cape, bpy.context.evaluated_depsgraph_get())
        seen["cloth"].append([list(p) for p in cloth])
        seen["pin_error"].append(max((cloth[i] - rig[i]).length for i in pins))
        bone = cape.matrix_world @ spine.matrix @ spine.bone.matrix_local.inverted()
        seen["pin_route"].append(max((bone @ cape.data.vertices[i].co - rig[i]).length
                                     for i in pins))  # the skinning by hand: another route
        seen["depth"].append(max([bvh.find_nearest(p)[3] for p in cloth if inside(bvh, p)],
                                 default=0.0))
        seen["gap"].append(min(bvh.find_nearest(p)[3] for p in cloth))
        if k == 0:  # the measure's own check: the torso's axis is a radius deep
            centre = character.matrix_world @ Vector(rigged_cape.TORSO[0])
            seen["probe"] = [inside(bvh, centre), bvh.find_nearest(centre)[3]]
    return seen


def keyframes() -> dict:
    """Per target key ``NAME@FRAME``: the cape's rms off it at its frame, and how far the
    add-on's target (the key evaluated on the rig) is from the key placed by hand by the
    cape's transform at that frame (its free vertices, which no bone moves)."""
    out = {}
    for index, key in enumerate(cape.data.shape_keys.key_blocks):
        frame = solving.bridge.frame_from_name(key.name)
        if frame is None:
            continue
        want = collect.shape_at(cape, scene, index, frame)
        scene.frame_set(frame)
        got, _ = world_mesh(cape, bpy.context.evaluated_depsgraph_get())
        free = set(range(len(want))) - set(collect.pinned(cape, "pins"))
        route = max((cape.matrix_world @ key.data[i].co - Vector(want[i])).length for i in free)
        rms = (sum((g - Vector(w)).length_squared for g, w in zip(got, want)) / len(got)) ** 0.5
        out[key.name] = {"frame": frame, "rms": rms, "route": route}
    return out


def dump(tag: str, extra: dict) -> dict:
    result = Path(cape[solving.RESULT])
    frames = len(solving.result_frames(result))
    cache = cape.modifiers[collect.MODIFIER]
    return {**extra, **measure(frames), "keyframes": keyframes(), "result": str(result),
            "misses_panel": settings.misses, "tag": tag,
            "cache": [cache.type, cache.frame_start, cache.filepath],
            "modifiers": [m.type for m in cape.modifiers]}


seen = {"fps": scene.render.fps / scene.render.fps_base, "frame_start": scene.frame_start,
        "blender": bpy.app.version_string}
if job.get("break_topology"):  # no result to re-solve; the character's faces built up
    try:
        bpy.ops.casadi_keyframe.resolve()
    except RuntimeError as err:
        seen["resolve_error"] = str(err)
    build = character.modifiers.new("Build", "BUILD")
    build.frame_start, build.frame_duration = scene.frame_start, 20
    try:
        seen["operator"] = list(bpy.ops.casadi_keyframe.solve())
    except RuntimeError as err:  # an operator's error report, raised in a script
        seen["error"] = str(err)
    seen["files"] = sorted(p.name for p in Path(job["folder"]).glob("*"))
elif "cancel_after" in job:
    seen["runs"] = [dump("cancelled", solve_and_cancel(job["cancel_after"]))]
else:
    began = time.monotonic()
    result = bpy.ops.casadi_keyframe.solve()
    seen["runs"] = [dump("solve", {"operator": list(result),
                                   "seconds": time.monotonic() - began})]
if "resolve_from" in job:  # a pose added later in the shot, re-solved from a frame on
    rigged_cape.add_target(cape, *job["resolve_target"])
    settings.options = job.get("resolve_options", "")
    scene.frame_set(scene.frame_start + job["resolve_from"])
    began = time.monotonic()
    result = bpy.ops.casadi_keyframe.resolve()
    seen["runs"].append(dump("resolve", {"operator": list(result),
                                         "seconds": time.monotonic() - began}))
with open(out_path, "w") as f:
    json.dump(seen, f)
print("bl_rig: done")
