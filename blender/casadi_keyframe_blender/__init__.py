"""casadi_keyframe for Blender: keyframe a cloth against shape keys, solved outside Blender.

Pick a mesh object, put its pinned vertices in a vertex group (``pins`` by default), give
it shape keys named ``NAME@FRAME`` (or keyed to 1.0 at a frame; other mesh objects named
``NAME@FRAME`` count too) and press Solve in the sidebar's "Keyframe Cloth" tab.  The mesh
objects of a collection named ``colliders`` are bodies the cloth touches, still or animated
(armatures, modifiers and shape keys as evaluated at each frame).  The add-on
writes the meshes as OBJ files (world space, metres, z up), runs ``casadi-keyframe solve
mesh_keyframes`` with the installed library (its path in the add-on's preferences) in a
subprocess, shows its progress and the misses, and plays the result through a Mesh Cache
modifier, one cache frame per scene frame from the scene's start (the solver's dt is the
scene's frame time).  It never imports casadi_keyframe into Blender's Python.
"""
from __future__ import annotations

import os
import queue
import subprocess
import tempfile
import threading
from pathlib import Path

import bpy
from bpy.props import FloatProperty, IntProperty, PointerProperty, StringProperty

from . import bridge

bl_info = {
    "name": "casadi_keyframe cloth keyframes",
    "author": "casadi_keyframe",
    "version": (0, 1, 0),
    "blender": (3, 4, 0),
    "location": "View3D > Sidebar > Keyframe Cloth",
    "description": "Solve a cloth that hits shape keys at frames (casadi-keyframe, in a "
                   "subprocess) and play it back through a Mesh Cache modifier",
    "category": "Physics",
}
MODIFIER = "casadi_keyframe"
COLLIDERS = "colliders"  # the collection whose mesh objects are bodies


class CKF_Preferences(bpy.types.AddonPreferences):
    bl_idname = __package__

    executable: StringProperty(
        name="casadi-keyframe command", subtype="FILE_PATH", default="casadi-keyframe",
        description="The casadi-keyframe command of the Python environment where the library "
                    "is installed, e.g. /home/me/casadi_keyframe/.venv/bin/casadi-keyframe")

    def draw(self, context):
        self.layout.prop(self, "executable")


class CKF_Settings(bpy.types.PropertyGroup):
    pins_group: StringProperty(name="Pins group", default="pins",
                               description="Vertex group of the pinned vertices")
    tolerance: FloatProperty(name="Tolerance (m)", default=0.01, min=0.0, precision=4,
                             description="rms distance to a target that counts as a hit")
    maxiter: IntProperty(name="Iterations", default=100, min=1)
    steps: IntProperty(name="Frames", default=0, min=0,
                       description="Frames to simulate from the scene's start (0: to the "
                                   "last keyframe)")
    folder: StringProperty(name="Work folder", subtype="DIR_PATH", default="",
                           description="Where the meshes and the result go (empty: "
                                       "//casadi_keyframe/OBJECT next to the .blend, or a "
                                       "temporary folder)")
    status: StringProperty(name="Status", default="")
    misses: StringProperty(name="Misses", default="")


def preferences(context):
    return context.preferences.addons[__package__].preferences


def world_points(matrix, points):
    return [tuple(matrix @ p.co) for p in points]


def _fcurves(id_data):
    """The F-curves animating ``id_data`` (slotted actions of 4.4+, or the old list)."""
    ad = getattr(id_data, "animation_data", None)
    if ad is None or ad.action is None:
        return []
    try:
        from bpy_extras import anim_utils
        bag = anim_utils.action_get_channelbag_for_slot(ad.action, ad.action_slot)
        return list(bag.fcurves) if bag is not None else []
    except (ImportError, AttributeError):
        return list(getattr(ad.action, "fcurves", []))


def keyed_frame(keys, block):
    """The first frame where shape key ``block``'s value is keyed to 1, or None."""
    path = f'key_blocks["{block.name}"].value'
    for curve in _fcurves(keys):
        if curve.data_path == path:
            full = [k.co[0] for k in curve.keyframe_points if k.co[1] >= 0.999]
            if full:
                return int(round(min(full)))
    return None


def collect_targets(obj, scene):
    """``[(scene frame, name, world points)]`` of the object's target shape keys and of the
    scene's mesh objects named ``NAME@FRAME``."""
    found, matrix = [], obj.matrix_world
    keys = obj.data.shape_keys
    if keys is not None:
        for block in keys.key_blocks:
            if block == keys.reference_key:
                continue
            frame = bridge.frame_from_name(block.name)
            frame = keyed_frame(keys, block) if frame is None else frame
            if frame is not None:
                found.append((frame, block.name, world_points(matrix, block.data)))
    for other in scene.objects:
        frame = bridge.frame_from_name(other.name)
        if other is obj or other.type != "MESH" or frame is None:
            continue
        if len(other.data.vertices) != len(obj.data.vertices):
            raise ValueError(f"target object {other.name} has {len(other.data.vertices)} "
                             f"vertices, {obj.name} {len(obj.data.vertices)}: a target must be "
                             f"a copy of the cloth in another shape")
        found.append((frame, other.name, world_points(other.matrix_world, other.data.vertices)))
    return sorted(found)


def collect_bodies(scene, depsgraph, folder, steps: int, cloth=None) -> list:
    """Write each mesh object of the ``colliders`` collection (but the ``cloth``) as a body
    file (world space, evaluated at each frame from the scene's start over ``steps`` frames
    and one more) and return the files."""
    collection = bpy.data.collections.get(COLLIDERS)
    objects = [o for o in (collection.all_objects if collection else [])
               if o.type == "MESH" and o is not cloth]
    if not objects:
        return []
    frames = {o.name: [] for o in objects}
    polygons = {}
    current = scene.frame_current
    try:
        for frame in range(scene.frame_start, scene.frame_start + steps + 2):
            scene.frame_set(frame)
            for o in objects:
                evaluated = o.evaluated_get(depsgraph)
                mesh = evaluated.to_mesh()
                faces = [list(p.vertices) for p in mesh.polygons]
                if polygons.setdefault(o.name, faces) != faces:
                    raise ValueError(f"collider {o.name} changes its faces at frame {frame}: "
                                     f"a body keeps its mesh's topology")
                frames[o.name].append(world_points(evaluated.matrix_world, mesh.vertices))
                evaluated.to_mesh_clear()
    finally:
        scene.frame_set(current)
    return [bridge.write_body(folder, f"collider_{bpy.path.clean_name(o.name)}",
                              frames[o.name], polygons[o.name]) for o in objects]


def work_folder(settings, obj) -> Path:
    if settings.folder:
        return Path(bpy.path.abspath(settings.folder))
    if bpy.data.filepath:
        return Path(bpy.path.abspath(f"//casadi_keyframe/{bpy.path.clean_name(obj.name)}"))
    return Path(tempfile.mkdtemp(prefix="casadi_keyframe_"))


def prepare(context):
    """Write the cloth and its targets, and return ``(command, out folder)``."""
    obj, scene = context.active_object, context.scene
    settings = scene.casadi_keyframe
    if obj is None or obj.type != "MESH":
        raise ValueError("select the cloth: a mesh object")
    keys = obj.data.shape_keys
    rest = keys.reference_key.data if keys is not None else obj.data.vertices
    start = scene.frame_start
    targets = [(f - start, name, pts) for f, name, pts in collect_targets(obj, scene)]
    if not targets:
        raise ValueError(f"{obj.name} has no targets: name shape keys NAME@FRAME (or key their "
                         f"value to 1 at a frame)")
    early = [f"{name} at frame {f + start}" for f, name, _ in targets if f < 1]
    if early:
        raise ValueError(f"targets must come after the scene's start frame {start}: "
                         f"{', '.join(early)}")
    group = obj.vertex_groups.get(settings.pins_group)
    pins = [] if group is None else [v.index for v in obj.data.vertices
                                     if any(g.group == group.index and g.weight > 0
                                            for g in v.groups)]
    folder = work_folder(settings, obj)
    folder.mkdir(parents=True, exist_ok=True)
    polygons = [list(p.vertices) for p in obj.data.polygons]
    cloth = folder / "cloth.obj"
    cloth.write_text(bridge.obj_text(world_points(obj.matrix_world, rest), polygons,
                                     f"{obj.name} rest shape, world space"))
    files = []
    for frame, name, pts in targets:
        path = folder / f"target_{frame:04d}.obj"
        path.write_text(bridge.obj_text(pts, polygons, f"{name}: result frame {frame}"))
        files.append((frame, path))
    steps = settings.steps or max(f for f, _ in files)
    bodies = collect_bodies(scene, context.evaluated_depsgraph_get(), folder, steps, obj)
    command = bridge.solve_command(
        preferences(context).executable, cloth=cloth, targets=files, pins=pins,
        dt=bridge.fps_fraction(scene.render.fps, scene.render.fps_base), steps=steps,
        out=folder / "result", maxiter=settings.maxiter, bodies=bodies)
    return command, folder / "result"


def finish(context, obj, out: Path, code: int) -> list[str]:
    """Read the misses, put the cache on ``obj`` and return the lines to show."""
    scene, settings = context.scene, context.scene.casadi_keyframe
    if code not in (0, 1, 3, 130, 143) or not (out / "summary.json").is_file():  # see solve --help
        raise RuntimeError(f"casadi-keyframe failed (exit code {code}): see the console")
    lines = bridge.describe_misses(bridge.read_misses(out), settings.tolerance,
                                   scene.frame_start)
    frames, start, rate = bridge.read_pc2(out / f"{bridge.PROBLEM}.pc2")
    inverse = [list(row) for row in obj.matrix_world.inverted()]
    local = bridge.write_pc2(out / f"{bpy.path.clean_name(obj.name)}_local.pc2",
                             bridge.to_local(frames, inverse), start, rate)
    mod = obj.modifiers.get(MODIFIER) or obj.modifiers.new(MODIFIER, "MESH_CACHE")
    mod.cache_format, mod.filepath = "PC2", str(local)
    mod.frame_start = scene.frame_start
    mod.time_mode, mod.play_mode, mod.frame_scale = "FRAME", "SCENE", 1.0
    mod.forward_axis, mod.up_axis = "POS_Y", "POS_Z"
    scene.frame_end = max(scene.frame_end, scene.frame_start + len(frames) - 1)
    settings.misses = "; ".join(lines)
    obj["casadi_keyframe_result"] = str(out)
    return lines


class CKF_OT_solve(bpy.types.Operator):
    """Solve the cloth onto its target shape keys with casadi-keyframe (in a subprocess)"""

    bl_idname = "casadi_keyframe.solve"
    bl_label = "Solve Keyframes"
    bl_options = {"REGISTER"}

    def execute(self, context):
        try:
            command, self.out = prepare(context)
        except (ValueError, OSError) as err:
            self.report({"ERROR"}, str(err))
            return {"CANCELLED"}
        self.obj = context.active_object
        print("casadi_keyframe:", " ".join(command))
        try:
            self.process = subprocess.Popen(command, stdout=subprocess.PIPE,
                                            stderr=subprocess.STDOUT, text=True, bufsize=1,
                                            env={**os.environ, "PYTHONUNBUFFERED": "1"})
        except OSError as err:
            self.report({"ERROR"}, f"cannot run {command[0]}: {err}; set the casadi-keyframe "
                                   f"command in the add-on's preferences")
            return {"CANCELLED"}
        self.lines, self.pending = queue.Queue(), ""
        threading.Thread(target=self._read, daemon=True).start()
        if bpy.app.background:  # headless: wait here
            while self.process.poll() is None or not self.lines.empty():
                self._drain(context, wait=0.2)
            return self._done(context)
        self.timer = context.window_manager.event_timer_add(0.25, window=context.window)
        context.window_manager.modal_handler_add(self)
        return {"RUNNING_MODAL"}

    def _read(self):
        for chunk in iter(lambda: self.process.stdout.read(256), ""):
            self.lines.put(chunk)

    def _drain(self, context, wait=0.0):
        try:
            chunk = self.lines.get(timeout=wait) if wait else self.lines.get_nowait()
        except queue.Empty:
            return
        lines, self.pending = bridge.progress_lines(chunk, self.pending)
        for line in lines:
            print("casadi-keyframe:", line)
            context.scene.casadi_keyframe.status = line[:200]
        if self.pending.strip():
            context.scene.casadi_keyframe.status = self.pending.strip()[:200]

    def modal(self, context, event):
        if event.type == "ESC":
            self.process.terminate()  # the solver writes its best result and stops
        if event.type != "TIMER":
            return {"PASS_THROUGH"}
        while not self.lines.empty():
            self._drain(context)
        if context.area is not None:
            context.area.tag_redraw()
        context.workspace.status_text_set("casadi-keyframe: "
                                          + context.scene.casadi_keyframe.status)
        if self.process.poll() is None:
            return {"PASS_THROUGH"}
        context.window_manager.event_timer_remove(self.timer)
        context.workspace.status_text_set(None)
        self._done(context)
        return {"FINISHED"}

    def _done(self, context):
        try:
            lines = finish(context, self.obj, self.out, self.process.wait())
        except (RuntimeError, OSError, ValueError, KeyError) as err:
            self.report({"ERROR"}, str(err))
            return {"CANCELLED"}
        for line in lines:
            self.report({"INFO"} if line.endswith(")") and "hit" in line else {"WARNING"}, line)
            print("casadi_keyframe:", line)
        return {"FINISHED"}


class CKF_OT_import_usd(bpy.types.Operator):
    """Import a casadi-keyframe USD result with the scene's frame rate and range set from it"""

    bl_idname = "casadi_keyframe.import_usd"
    bl_label = "Import casadi-keyframe USD"
    filepath: StringProperty(subtype="FILE_PATH")

    def execute(self, context):
        rate = usd_frame_rate(self.filepath)
        if rate is None:
            self.report({"ERROR"}, f"{self.filepath}: no framesPerSecond in the stage and no "
                                   f"result.npz beside it")
            return {"CANCELLED"}
        bpy.ops.wm.usd_import(filepath=self.filepath, set_frame_range=True)
        set_frame_rate(context.scene, rate)
        return {"FINISHED"}

    def invoke(self, context, event):
        context.window_manager.fileselect_add(self)
        return {"RUNNING_MODAL"}


def usd_frame_rate(path):
    """The frame rate of a USD result: ``framesPerSecond`` of a text stage, else ``1 / dt``
    from the ``result.npz`` beside it (Blender's importer sets the frame range, not the
    rate, and Blender's Python has no pxr module)."""
    path = Path(path)
    head = path.read_bytes()[:4096]
    if head.startswith(b"#usda"):
        for line in head.decode("utf8", "replace").splitlines():
            if "framesPerSecond" in line:
                return float(line.split("=")[1])
    npz = path.with_name("result.npz")
    if npz.is_file():
        import numpy as np  # Blender bundles numpy
        with np.load(npz, allow_pickle=False) as data:
            return 1.0 / float(data["dt"])
    return None


def set_frame_rate(scene, rate: float) -> None:
    """``scene.render.fps`` and ``fps_base`` for ``rate`` frames per second."""
    fps = max(1, round(rate))
    scene.render.fps, scene.render.fps_base = fps, fps / rate


class CKF_PT_panel(bpy.types.Panel):
    bl_label = "Keyframe Cloth"
    bl_idname = "CKF_PT_panel"
    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = "Keyframe Cloth"

    def draw(self, context):
        settings, layout = context.scene.casadi_keyframe, self.layout
        for name in ("pins_group", "tolerance", "maxiter", "steps", "folder"):
            layout.prop(settings, name)
        layout.operator(CKF_OT_solve.bl_idname)
        layout.operator(CKF_OT_import_usd.bl_idname)
        if settings.status:
            layout.label(text=settings.status[:80])
        for line in filter(None, settings.misses.split("; ")):
            layout.label(text=line, icon="CHECKMARK" if ": hit" in line else "ERROR")


CLASSES = (CKF_Preferences, CKF_Settings, CKF_OT_solve, CKF_OT_import_usd, CKF_PT_panel)


def register():
    for cls in CLASSES:
        bpy.utils.register_class(cls)
    bpy.types.Scene.casadi_keyframe = PointerProperty(type=CKF_Settings)


def unregister():
    del bpy.types.Scene.casadi_keyframe
    for cls in reversed(CLASSES):
        bpy.utils.unregister_class(cls)
