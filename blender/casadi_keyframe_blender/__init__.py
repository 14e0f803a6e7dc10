"""casadi_keyframe for Blender: keyframe a cloth against shape keys, solved outside Blender.

Pick a mesh object, put its pinned vertices in a vertex group (``pins`` by default), give
it shape keys named ``NAME@FRAME`` (or keyed to 1.0 at a frame; other mesh objects named
``NAME@FRAME`` count too) and press Solve in the sidebar's "Keyframe Cloth" tab.  Pinned
vertices that move with the cloth's rig (parenting, an armature, hooks) carry the cloth:
their evaluated motion is sent as the pins' motion.  The mesh objects of a collection named
``colliders`` are bodies the cloth touches, still or animated (armatures, modifiers and
shape keys as evaluated at each frame).  The add-on writes the meshes as OBJ and PC2 files
(world space, metres, z up), runs ``casadi-keyframe solve mesh_keyframes`` with the
installed library (its path in the add-on's preferences) in a subprocess, shows its
progress and time left in the status bar (Esc stops it keeping its best point), shows the
misses, and plays the result through a Mesh Cache modifier, one cache frame per scene frame
from the scene's start (the solver's dt is the scene's frame time).  "Re-solve from Current
Frame" keeps the last result up to the current frame and solves what follows against the
scene as it is now.  It never imports casadi_keyframe into Blender's Python.
"""
from __future__ import annotations

from pathlib import Path

import bpy
from bpy.props import FloatProperty, IntProperty, PointerProperty, StringProperty

from . import collect, solving
from .solving import RESULT

bl_info = {
    "name": "casadi_keyframe cloth keyframes",
    "author": "casadi_keyframe",
    "version": (0, 2, 0),
    "blender": (3, 4, 0),
    "location": "View3D > Sidebar > Keyframe Cloth",
    "description": "Solve a cloth that hits shape keys at frames (casadi-keyframe, in a "
                   "subprocess) and play it back through a Mesh Cache modifier",
    "category": "Physics",
}
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
    options: StringProperty(name="Solver options", default="",
                            description="More casadi-keyframe solve options, as on its "
                                        "command line, e.g. --finish land --time-limit 300")
    status: StringProperty(name="Status", default="")
    misses: StringProperty(name="Misses", default="")


def preferences(context):
    return context.preferences.addons[__package__].preferences


class Solving:
    """A solve's operator: the files written and the command made by ``prepare``, the
    solver run in a subprocess, watched by a timer (progress and time left in the status
    bar; Esc stops it keeping its best point), its result loaded as the Mesh Cache."""

    def prepare(self, context):
        """``(command, out folder)`` of this solve."""
        raise NotImplementedError

    def execute(self, context):
        try:
            command, self.out = self.prepare(context)
        except (ValueError, OSError) as err:
            self.report({"ERROR"}, str(err))
            return {"CANCELLED"}
        self.obj = context.active_object
        print("casadi_keyframe:", " ".join(command))
        try:
            self.run = solving.SolveProcess(command)
        except OSError as err:
            self.report({"ERROR"}, f"cannot run {command[0]}: {err}; set the casadi-keyframe "
                                   f"command in the add-on's preferences")
            return {"CANCELLED"}
        if bpy.app.background:  # headless: wait here
            return self._done(context, self.run.wait())
        self.timer = context.window_manager.event_timer_add(0.25, window=context.window)
        context.window_manager.modal_handler_add(self)
        return {"RUNNING_MODAL"}

    def modal(self, context, event):
        if event.type == "ESC" and event.value == "PRESS":
            self.run.cancel()  # the solver writes its best point and stops
            return {"RUNNING_MODAL"}
        if event.type != "TIMER":
            return {"PASS_THROUGH"}
        for line in self.run.drain():
            print("casadi-keyframe:", line)
        context.scene.casadi_keyframe.status = self.run.last[:200]
        context.workspace.status_text_set("casadi-keyframe (Esc stops, keeping the best "
                                          "point): " + self.run.status())
        if context.area is not None:
            context.area.tag_redraw()
        if self.run.running:
            return {"PASS_THROUGH"}
        context.window_manager.event_timer_remove(self.timer)
        context.workspace.status_text_set(None)
        return self._done(context, self.run.wait())

    def _done(self, context, code: int):
        context.scene.casadi_keyframe.status = self.run.last[:200]
        try:
            lines = solving.finish(context, self.obj, self.out, code)
        except (RuntimeError, OSError, ValueError, KeyError) as err:
            self.report({"ERROR"}, str(err))
            return {"CANCELLED"}
        if self.run.cancelled_at is not None:
            self.report({"WARNING"}, "stopped: the best point found so far is loaded")
        for line in lines:
            self.report({"INFO"} if line.endswith(")") and "hit" in line else {"WARNING"}, line)
            print("casadi_keyframe:", line)
        return {"FINISHED"}


class CKF_OT_solve(Solving, bpy.types.Operator):
    """Solve the cloth onto its target shape keys with casadi-keyframe (in a subprocess)"""

    bl_idname = "casadi_keyframe.solve"
    bl_label = "Solve Keyframes"
    bl_options = {"REGISTER"}

    def prepare(self, context):
        return collect.prepare(context, preferences(context).executable)


class CKF_OT_resolve(Solving, bpy.types.Operator):
    """Keep the last result up to the current frame and solve the frames after it again,
    against the scene as it is now (changed keys, colliders, rig)"""

    bl_idname = "casadi_keyframe.resolve"
    bl_label = "Re-solve from Current Frame"
    bl_options = {"REGISTER"}

    def prepare(self, context):
        obj, scene = context.active_object, context.scene
        last = obj.get(RESULT) if obj is not None else None
        if not last or not (Path(last) / "result.npz").is_file():
            raise ValueError("no result to keep: press Solve Keyframes first")
        frame = scene.frame_current - scene.frame_start
        if frame < 1:
            raise ValueError(f"go to a frame after the scene's start ({scene.frame_start}): "
                             f"the motion up to the current frame is kept")
        return collect.prepare(context, preferences(context).executable, resume=last,
                               from_frame=frame)


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
        for name in ("pins_group", "tolerance", "maxiter", "steps", "folder", "options"):
            layout.prop(settings, name)
        layout.operator(CKF_OT_solve.bl_idname)
        obj = context.active_object
        row = layout.row()
        row.enabled = obj is not None and bool(obj.get(RESULT))
        row.operator(CKF_OT_resolve.bl_idname, text=f"Re-solve from Frame "
                                                   f"{context.scene.frame_current}")
        layout.operator(CKF_OT_import_usd.bl_idname)
        if settings.status:
            layout.label(text=settings.status[:80])
        for line in filter(None, settings.misses.split("; ")):
            layout.label(text=line, icon="CHECKMARK" if ": hit" in line else "ERROR")


CLASSES = (CKF_Preferences, CKF_Settings, CKF_OT_solve, CKF_OT_resolve, CKF_OT_import_usd,
           CKF_PT_panel)


def register():
    for cls in CLASSES:
        bpy.utils.register_class(cls)
    bpy.types.Scene.casadi_keyframe = PointerProperty(type=CKF_Settings)


def unregister():
    del bpy.types.Scene.casadi_keyframe
    for cls in reversed(CLASSES):
        bpy.utils.unregister_class(cls)
