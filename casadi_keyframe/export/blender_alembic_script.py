"""Run inside Blender (``blender -b --python THIS -- REST PC2 OUT FRAMES FPS``, or a Python
with the ``bpy`` module): import the rest OBJ (z up), play the PC2 through a Mesh Cache
modifier at FPS frames per second from frame 0, and export FRAMES frames as Alembic to OUT.
Not imported by the library (see :mod:`.alembic`)."""
import sys

import bpy

rest, pc2, out, frames, fps = sys.argv[sys.argv.index("--") + 1:][:5]
if "alembic_export" not in dir(bpy.ops.wm):
    print(f"NO-ALEMBIC: Blender {bpy.app.version_string} was built without Alembic")
    sys.exit(3)
frames, fps = int(frames), float(fps)
bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.ops.wm.obj_import(filepath=rest, forward_axis="Y", up_axis="Z")
obj = bpy.context.selected_objects[0]
mod = obj.modifiers.new("cache", "MESH_CACHE")
mod.cache_format, mod.filepath, mod.frame_start = "PC2", pc2, 0
scene = bpy.context.scene
scene.render.fps = max(1, round(fps))
scene.render.fps_base = scene.render.fps / fps
scene.frame_start, scene.frame_end = 0, frames - 1
bpy.ops.wm.alembic_export(filepath=out, start=0, end=frames - 1, selected=False,
                          uvs=False, normals=False, face_sets=False)
