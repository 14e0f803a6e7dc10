"""Run by a Blender Python (``python bl_addon.py -- JOB.json OUT.json``), not by pytest: the
add-on installed from its zip, a small sheet built as a user would (an object moved off the
origin, a ``pins`` vertex group, one target shape key named ``wave@FRAME`` and one keyed to
1 at its frame), Solve pressed headless, and what the object's Mesh Cache then shows at the
target frames dumped with the shape keys' own vertices (object space)."""
import json
import sys

import bpy
import addon_utils  # noqa: E402 (importable once bpy is)

job_path, out_path = sys.argv[sys.argv.index("--") + 1:][:2]
job = json.loads(open(job_path).read())
bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.ops.preferences.addon_install(filepath=job["addon"], overwrite=True)
addon_utils.enable("casadi_keyframe_blender", default_set=True)
prefs = bpy.context.preferences.addons["casadi_keyframe_blender"].preferences
prefs.executable = job["executable"]

scene = bpy.context.scene
scene.render.fps, scene.render.fps_base = job["fps"], 1.0
scene.frame_start = job["start"]
mesh = bpy.data.meshes.new("sheet")
mesh.from_pydata(job["vertices"], [], job["quads"])
obj = bpy.data.objects.new("Sheet", mesh)
scene.collection.objects.link(obj)
obj.location = job["location"]
bpy.context.view_layer.objects.active = obj
obj.select_set(True)
group = obj.vertex_groups.new(name="pins")
group.add(job["pins"], 1.0, "REPLACE")
obj.shape_key_add(name="Basis")
wave = obj.shape_key_add(name=f"wave@{job['wave_frame']}")
for v, p in zip(wave.data, job["wave"]):
    v.co = p
fold = obj.shape_key_add(name="fold")
for v, p in zip(fold.data, job["fold"]):
    v.co = p
fold.value = 0.0
fold.keyframe_insert("value", frame=job["start"])
fold.value = 1.0
fold.keyframe_insert("value", frame=job["fold_frame"])
settings = scene.casadi_keyframe
settings.tolerance, settings.maxiter, settings.folder = job["tolerance"], job["maxiter"], job["folder"]

result = bpy.ops.casadi_keyframe.solve()
bpy.context.view_layer.update()
seen = {"operator": list(result), "misses": settings.misses, "status": settings.status,
        "fps": scene.render.fps / scene.render.fps_base, "frame_end": scene.frame_end,
        "modifiers": [(m.type, getattr(m, "frame_start", None)) for m in obj.modifiers]}
for name, frame in (("wave", job["wave_frame"]), ("fold", job["fold_frame"])):
    scene.frame_set(frame)
    ev = obj.evaluated_get(bpy.context.evaluated_depsgraph_get())
    got = ev.to_mesh()
    seen[name] = {"frame": frame, "animated": [list(v.co) for v in got.vertices],
                  "target": [list(v.co) for v in obj.data.shape_keys.key_blocks[
                      wave.name if name == "wave" else "fold"].data]}
    ev.to_mesh_clear()
with open(out_path, "w") as f:
    json.dump(seen, f)
print("bl_addon: done")
