"""Run by Blender (``blender -b --python tests/blender_mesh_cache.py -- REST PC2 OBJ OUT
FRAME...``), not by pytest: import the rest OBJ as the README says (Forward Y, Up Z), add a
Mesh Cache modifier reading the PC2 with Frame Start 1, and dump the evaluated vertices at
scene frame FRAME + 1 for each result FRAME, and those of one imported OBJ of the sequence,
as JSON to OUT.  Blender's Python may lack numpy: plain lists only."""
import json
import sys

import bpy

argv = sys.argv[sys.argv.index("--") + 1:]
rest, pc2, seq, out = argv[:4]
frames = [int(f) for f in argv[4:]]
bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.ops.wm.obj_import(filepath=rest, forward_axis='Y', up_axis='Z')
obj = bpy.context.selected_objects[0]
mod = obj.modifiers.new("cache", 'MESH_CACHE')
mod.cache_format = 'PC2'
mod.filepath = pc2
mod.frame_start = 1
print("defaults", mod.forward_axis, mod.up_axis, mod.time_mode, mod.play_mode, mod.frame_scale)
scene = bpy.context.scene
res = {}
for f in frames:
    scene.frame_set(f + 1)
    ev = obj.evaluated_get(bpy.context.evaluated_depsgraph_get())
    res[f] = [list(v.co) for v in ev.to_mesh().vertices]
bpy.ops.wm.obj_import(filepath=seq, forward_axis='Y', up_axis='Z')
one = bpy.context.selected_objects[0]
res["seq"] = [list(v.co) for v in one.data.vertices]
with open(out, "w") as f:
    json.dump(res, f)
