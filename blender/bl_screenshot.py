"""Run by a Blender Python (``python bl_screenshot.py -- JOB.json``; see
``make_screenshot.py``), not by the library: the README's walkthrough inside Blender with
the add-on (the sheet imported from its OBJ, the wave and fold as shape keys named
``NAME@FRAME``, a ``pins`` group on the top corners, Solve), then one Workbench render (the
viewport's solid shading, headless) per ``[target, frame]`` of ``renders``: the solved cloth
in blue, the target's shape key as a red wireframe.  Writes ``frame_F.png`` per render and
``seen.json`` (the add-on's misses and the rms between the cached cloth and the shape key
at each render)."""
import json
import math
import sys
from pathlib import Path

import bpy
import addon_utils  # noqa: E402 (importable once bpy is)
from mathutils import Vector

from bl_workbench import workbench  # noqa: E402 (beside this script)

job = json.loads(Path(sys.argv[sys.argv.index("--") + 1]).read_text())
out = Path(job["out"])
bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.ops.preferences.addon_install(filepath=job["addon"], overwrite=True)
addon_utils.enable("casadi_keyframe_blender", default_set=True)
bpy.context.preferences.addons["casadi_keyframe_blender"].preferences.executable = job["executable"]
scene = bpy.context.scene
scene.render.fps, scene.frame_start = 60, 1

bpy.ops.wm.obj_import(filepath=job["sheet"], forward_axis="Y", up_axis="Z")
cloth = bpy.context.selected_objects[0]
bpy.context.view_layer.objects.active = cloth
cloth.vertex_groups.new(name="pins").add(job["pins"], 1.0, "REPLACE")
cloth.shape_key_add(name="Basis")
targets = {}
for name, (path, frame) in job["targets"].items():
    bpy.ops.wm.obj_import(filepath=path, forward_axis="Y", up_axis="Z")
    shape = bpy.context.selected_objects[0]
    key = cloth.shape_key_add(name=f"{name}@{frame}")
    for v, w in zip(key.data, shape.data.vertices):
        v.co = w.co
    targets[name] = (frame, shape)
bpy.context.view_layer.objects.active = cloth
for obj in bpy.context.selected_objects:
    obj.select_set(False)
cloth.select_set(True)
scene.casadi_keyframe.folder = str(out / "work")
assert bpy.ops.casadi_keyframe.solve() == {"FINISHED"}

blue = bpy.data.materials.new("cloth")
blue.diffuse_color = (0.35, 0.55, 0.85, 1.0)
red = bpy.data.materials.new("target")
red.diffuse_color = (0.85, 0.1, 0.1, 1.0)
cloth.data.materials.append(blue)
for frame, shape in targets.values():  # the target meshes, drawn as wireframes
    shape.data.materials.append(red)
    wire = shape.modifiers.new("wire", "WIREFRAME")
    wire.thickness, wire.use_replace = 0.004, True
    shape.hide_render = True
camera = workbench(scene, 720, 720, lens=50)
camera.location = Vector(job["camera"])
aim = Vector(job["aim"]) - camera.location
camera.rotation_euler = aim.to_track_quat("-Z", "Y").to_euler()

seen = {"misses": scene.casadi_keyframe.misses, "rms": {}}
for name, frame in job["renders"]:  # a keyframe, or a frame on the way (the wire is off)
    shape = targets[name][1]
    for other in targets.values():
        other[1].hide_render = other[1] is not shape
    scene.frame_set(frame)
    ev = cloth.evaluated_get(bpy.context.evaluated_depsgraph_get())
    got = [v.co.copy() for v in ev.to_mesh().vertices]
    ev.to_mesh_clear()
    err = [(a - b.co).length ** 2 for a, b in zip(got, shape.data.vertices)]
    seen["rms"][f"{name}@{frame}"] = math.sqrt(sum(err) / len(err))
    scene.render.filepath = str(out / f"frame_{frame}.png")
    bpy.ops.render.render(write_still=True)
(out / "seen.json").write_text(json.dumps(seen))
print("bl_screenshot: done", seen)
