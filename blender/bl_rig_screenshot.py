"""Run by a Blender Python (``python bl_rig_screenshot.py -- JOB.json``; see
``make_rig_screenshot.py``), not by the library: the rigged example (``rigged_cape.py``)
built, the add-on's Solve pressed on its cape, then one Workbench render per frame of
``renders`` from a camera that follows the character (beside it, a little behind): the cape in blue, the character in
grey, the cape's target shape key as a red wireframe at its frame.  Writes ``rig_F.png`` per
render and ``seen.json`` (the add-on's misses, the solve's seconds, the cape's rms off its
target at the keyframe)."""
import json
import sys
import time
from pathlib import Path

import bpy
import addon_utils  # noqa: E402 (importable once bpy is)
from mathutils import Vector

job = json.loads(Path(sys.argv[sys.argv.index("--") + 1]).read_text())
out = Path(job["out"])
bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.ops.preferences.addon_install(filepath=job["addon"], overwrite=True)
addon_utils.enable("casadi_keyframe_blender", default_set=True)
bpy.context.preferences.addons["casadi_keyframe_blender"].preferences.executable = job["executable"]
from casadi_keyframe_blender import collect  # noqa: E402 (once enabled)

sys.path.insert(0, str(Path(__file__).resolve().parent))
import rigged_cape  # noqa: E402
from bl_workbench import workbench  # noqa: E402

objects = rigged_cape.build(**job["build"])
cape, character, rig = objects["cape"], objects["character"], objects["rig"]
scene = bpy.context.scene
scene.casadi_keyframe.folder = str(out / "work")
scene.casadi_keyframe.maxiter = job["maxiter"]
began = time.monotonic()
assert bpy.ops.casadi_keyframe.solve() == {"FINISHED"}
seconds = time.monotonic() - began

key_index, key = next((i, k) for i, k in enumerate(cape.data.shape_keys.key_blocks)
                      if "@" in k.name)
key_frame = collect.bridge.frame_from_name(key.name)
target_mesh = bpy.data.meshes.new("target")
target_mesh.from_pydata(collect.shape_at(cape, scene, key_index, key_frame), [],
                        [list(p.vertices) for p in cape.data.polygons])
target = bpy.data.objects.new("target", target_mesh)
scene.collection.objects.link(target)
for obj, colour in ((cape, (0.35, 0.55, 0.85, 1.0)), (character, (0.75, 0.72, 0.68, 1.0)),
                    (target, (0.85, 0.1, 0.1, 1.0))):
    material = bpy.data.materials.new(obj.name)
    material.diffuse_color = colour
    obj.data.materials.append(material)
wire = target.modifiers.new("wire", "WIREFRAME")
wire.thickness, wire.use_replace = 0.006, True

camera = workbench(scene, 560, 720, lens=50)

seen = {"misses": scene.casadi_keyframe.misses, "seconds": seconds, "key_frame": key_frame,
        "walked": {}, "turned": {}}
for frame in job["renders"]:
    scene.frame_set(frame)
    seen["walked"][frame] = rig.matrix_world.translation.length
    seen["turned"][frame] = rig.matrix_world.to_euler().z
    target.hide_render = frame != key_frame
    centre = rig.matrix_world @ Vector((0.0, 0.0, 1.05))
    behind = rig.matrix_world.to_3x3() @ Vector(job["camera"])  # in the rig's frame
    camera.location = centre + behind
    camera.rotation_euler = (centre - camera.location).to_track_quat("-Z", "Y").to_euler()
    scene.render.filepath = str(out / f"rig_{frame}.png")
    bpy.ops.render.render(write_still=True)
(out / "seen.json").write_text(json.dumps(seen))
print("bl_rig_screenshot: done", seen)
