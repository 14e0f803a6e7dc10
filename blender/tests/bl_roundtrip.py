"""Run by a Blender Python (``python bl_roundtrip.py -- JOB.json OUT.json`` with the bpy
module, or ``blender -b --python bl_roundtrip.py -- ...``), not by pytest.  JOB names the
files a test exported and the frames to look at; for each it imports the file the way a
user would and dumps what Blender sees: world-space vertices (or instance positions and
headings) at those frames, the scene's frame rate and range, the instance count.  Blender's
Python may lack numpy: plain lists only."""
import json
import sys

import bpy
import addon_utils  # noqa: E402 (importable once bpy is)

job_path, out_path = sys.argv[sys.argv.index("--") + 1:][:2]
job = json.loads(open(job_path).read())
frames = job["frames"]
seen = {"blender": bpy.app.version_string}


def fresh():
    bpy.ops.wm.read_factory_settings(use_empty=True)
    if job.get("addon"):
        enable_addon(job["addon"])


def enable_addon(zip_path):
    bpy.ops.preferences.addon_install(filepath=zip_path, overwrite=True)
    addon_utils.enable("casadi_keyframe_blender", default_set=True)


def scene_info():
    s = bpy.context.scene
    return {"fps": s.render.fps / s.render.fps_base, "frame_start": s.frame_start,
            "frame_end": s.frame_end}


def vertices(obj, frame):
    bpy.context.scene.frame_set(frame)
    ev = obj.evaluated_get(bpy.context.evaluated_depsgraph_get())
    mesh = ev.to_mesh()
    out = [list(obj.matrix_world @ v.co) for v in mesh.vertices]
    ev.to_mesh_clear()
    return out


def mesh_object(name):
    return next(o for o in bpy.context.scene.objects if o.type == "MESH" and o.name == name)


if "usd" in job:  # the cloth's stage, through the add-on's import (which sets the rate)
    fresh()
    bpy.ops.wm.usd_import(filepath=job["usd"], set_frame_range=True)
    seen["usd_importer_alone"] = scene_info()
    fresh()
    bpy.ops.casadi_keyframe.import_usd(filepath=job["usd"])
    obj = mesh_object("Cloth")
    seen["usd"] = {**scene_info(), "frames": {f: vertices(obj, f) for f in frames}}

if "pc2" in job:  # rest OBJ + Mesh Cache, as the README's clicks
    fresh()
    bpy.ops.wm.obj_import(filepath=job["rest"], forward_axis="Y", up_axis="Z")
    obj = bpy.context.selected_objects[0]
    mod = obj.modifiers.new("cache", "MESH_CACHE")
    mod.cache_format, mod.filepath, mod.frame_start = "PC2", job["pc2"], 1
    seen["pc2"] = {"frames": {f: vertices(obj, f + 1) for f in frames}}

if "abc" in job:
    fresh()
    bpy.context.scene.render.fps = job["fps"]  # Blender reads Alembic on the scene's clock
    bpy.ops.wm.alembic_import(filepath=job["abc"], set_frame_range=True)
    obj = next(o for o in bpy.context.scene.objects if o.type == "MESH")
    seen["abc"] = {**scene_info(), "frames": {f: vertices(obj, f) for f in frames}}

if "flock" in job:
    fresh()
    bpy.ops.casadi_keyframe.import_usd(filepath=job["flock"])
    out = {**scene_info(), "frames": {}}
    for f in frames:
        bpy.context.scene.frame_set(f)
        graph = bpy.context.evaluated_depsgraph_get()
        out["frames"][f] = [
            {"proto": i.object.name, "position": list(i.matrix_world.translation),
             "heading": list(i.matrix_world.to_3x3() @ __import__("mathutils").Vector((1, 0, 0)))}
            for i in graph.object_instances if i.is_instance]
    seen["flock"] = out

with open(out_path, "w") as f:
    json.dump(seen, f)
print("bl_roundtrip: done")
