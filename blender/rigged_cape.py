"""The add-on's rigged example, generated (no downloads): a character (a capsule body and
a head) skinned to an armature that starts from rest, walks forward and turns left, with a
cape sewn at its shoulders and a target pose for the cape at a frame.

* ``Rig``: an armature (bones ``hips``, ``spine``, ``head``) whose object walks and turns;
  its hips bob and its spine leans into the walk (pose bones keyed every frame).
* ``Character``: the body mesh, parented to the rig and deformed by it (an Armature
  modifier, vertex groups named after the bones), in the ``colliders`` collection.
* ``Cape``: a ``cols`` x ``rows`` grid hanging behind the back, parented to the rig; its
  top row is the ``pins`` vertex group and is skinned to the ``spine`` bone, so the pinned
  vertices follow the shoulders; the rest is for the solver.  Its shape key
  ``flare@FRAME`` is the target: the cape lifted backwards by ``flare`` degrees about its
  top row and bent, as the rig places it at that frame.

Run in a Blender Python: ``build()`` from a script, or to save the scene::

    .venv-blender/bin/python blender/rigged_cape.py -- rigged_cape.blend
"""
from __future__ import annotations

import math
import sys

import bpy

TORSO = ((0.0, 0.0, 0.92), (0.0, 0.0, 1.34), 0.17)  # axis ends and radius (m)
HEAD = ((0.0, 0.0, 1.63), (0.0, 0.0, 1.69), 0.10)  # a short capsule
BACK_GAP = 0.035  # m between the back and the hanging cape
SHOULDER, LENGTH, WIDTH = 1.40, 0.8, 0.40  # the cape's top height, its length and width


def capsule(a, b, radius, around=16, rings=4):
    """``(vertices, faces)`` of a closed capsule about the segment ``a``-``b`` (along z,
    ``a`` below ``b``) with outward faces."""
    verts = [(a[0], a[1], a[2] - radius)]
    for end, lo, hi in ((a, -math.pi / 2, 0.0), (b, 0.0, math.pi / 2)):
        steps = [lo + (hi - lo) * k / rings for k in range(1, rings + 1)] if end is a else \
            [lo + (hi - lo) * k / rings for k in range(rings)]
        for t in steps:
            for k in range(around):
                p = 2 * math.pi * k / around
                verts.append((end[0] + radius * math.cos(t) * math.cos(p),
                              end[1] + radius * math.cos(t) * math.sin(p),
                              end[2] + radius * math.sin(t)))
    verts.append((b[0], b[1], b[2] + radius))
    ring_count, top = 2 * rings, len(verts) - 1
    faces = [(0, 1 + (k + 1) % around, 1 + k) for k in range(around)]
    for r in range(ring_count - 1):
        for k in range(around):
            i, j = 1 + r * around + k, 1 + r * around + (k + 1) % around
            faces.append((i, j, j + around, i + around))
    last = 1 + (ring_count - 1) * around
    faces += [(last + k, last + (k + 1) % around, top) for k in range(around)]
    return verts, faces


def character_mesh():
    """The body and the head as one mesh of two closed pieces, with the vertex indices of
    each piece."""
    torso_v, torso_f = capsule(*TORSO)
    head_v, head_f = capsule(*HEAD)
    n = len(torso_v)
    faces = torso_f + [tuple(i + n for i in f) for f in head_f]
    return torso_v + head_v, faces, range(n), range(n, n + len(head_v))


def make_rig(scene):
    """The armature object ``Rig`` with bones hips > spine > head (z up, facing +y)."""
    rig = bpy.data.objects.new("Rig", bpy.data.armatures.new("Rig"))
    scene.collection.objects.link(rig)
    bpy.context.view_layer.objects.active = rig
    bpy.ops.object.mode_set(mode="EDIT")
    bones = rig.data.edit_bones
    parent = None
    for name, head, tail in (("hips", 0.80, 1.10), ("spine", 1.10, SHOULDER + 0.05),
                             ("head", SHOULDER + 0.05, 1.80)):
        bone = bones.new(name)
        bone.head, bone.tail, bone.parent = (0, 0, head), (0, 0, tail), parent
        bone.use_connect = parent is not None
        parent = bone
    bpy.ops.object.mode_set(mode="OBJECT")
    return rig


def skin(obj, rig, weights: dict):
    """Parent ``obj`` to ``rig`` with an Armature modifier; ``weights`` maps a bone name
    to ``{vertex: weight}``."""
    obj.parent = rig
    for bone, verts in weights.items():
        group = obj.vertex_groups.get(bone) or obj.vertex_groups.new(name=bone)
        for v, w in verts.items():
            group.add([v], w, "REPLACE")
    mod = obj.modifiers.new("Armature", "ARMATURE")
    mod.object = rig


def make_character(scene, rig):
    verts, faces, torso, head = character_mesh()
    mesh = bpy.data.meshes.new("Character")
    mesh.from_pydata(verts, [], faces)
    mesh.validate()
    obj = bpy.data.objects.new("Character", mesh)
    colliders = bpy.data.collections.new("colliders")
    scene.collection.children.link(colliders)
    colliders.objects.link(obj)
    low, high = 1.0, 1.2  # the hips hand the torso to the spine between these heights
    spine = {v: min(max((verts[v][2] - low) / (high - low), 0.0), 1.0) for v in torso}
    skin(obj, rig, {"hips": {v: 1 - w for v, w in spine.items() if w < 1},
                    "spine": {v: w for v, w in spine.items() if w > 0},
                    "head": {v: 1.0 for v in head}})
    return obj


def make_cape(scene, rig, cols: int, rows: int):
    """The cape grid behind the back, vertex ``r * cols + c`` at row ``r`` (0: the top)."""
    y = -(TORSO[2] + BACK_GAP)
    verts = [(-WIDTH / 2 + WIDTH * c / (cols - 1), y, SHOULDER - LENGTH * r / (rows - 1))
             for r in range(rows) for c in range(cols)]
    faces = [(r * cols + c, r * cols + c + 1, (r + 1) * cols + c + 1, (r + 1) * cols + c)
             for r in range(rows - 1) for c in range(cols - 1)]
    mesh = bpy.data.meshes.new("Cape")
    mesh.from_pydata(verts, [], faces)
    obj = bpy.data.objects.new("Cape", mesh)
    scene.collection.objects.link(obj)
    top = list(range(cols))
    obj.vertex_groups.new(name="pins").add(top, 1.0, "REPLACE")
    skin(obj, rig, {"spine": {v: 1.0 for v in top}})
    return obj


def add_target(cape, frame: int, flare: float):
    """Shape key ``flare@FRAME``: the cape swung backwards, ``flare`` degrees from hanging
    straight down at its top row and curling on to 1.4 times that at its hem, each column
    bent along an arc (its length kept: a pose the cloth can take without stretching).
    Called again, it reshapes the key."""
    if cape.data.shape_keys is None:
        cape.shape_key_add(name="Basis")
    key = (cape.data.shape_keys.key_blocks.get(f"flare@{frame}")
           or cape.shape_key_add(name=f"flare@{frame}"))
    key.value = 0.0  # a target, not a shape to show
    top = cape.data.vertices[0].co
    start = math.radians(flare)
    bend = 0.4 * start / LENGTH  # radians per metre down the cape
    for v, point in zip(cape.data.vertices, key.data):
        s = top.z - v.co.z  # arc length down the cape from its top row
        back = (math.cos(start) - math.cos(start + bend * s)) / bend  # towards -y
        down = (math.sin(start + bend * s) - math.sin(start)) / bend
        point.co = (v.co.x, top.y - back, top.z - down)
    return key


def walk_path(frames: int, fps: float, speed: float, turn: float):
    """Per frame (from 0) the rig's ``(x, y, heading)``: it starts at rest, speeds up to
    ``speed`` m/s over the first 0.6 s, and turns left by ``turn`` degrees in the middle
    half of the shot (smooth steps), walking where it faces (+y at heading 0)."""
    def smooth(t):
        t = min(max(t, 0.0), 1.0)
        return t * t * (3 - 2 * t)
    x = y = 0.0
    out = []
    for f in range(frames):
        t = f / fps
        heading = math.radians(turn) * smooth((f - 0.25 * frames) / (0.5 * frames))
        v = speed * smooth(t / 0.6)
        out.append((x, y, heading))
        x, y = x - v * math.sin(heading) / fps, y + v * math.cos(heading) / fps
    return out


def animate(rig, start: int, frames: int, fps: float, speed: float, turn: float):
    """Key the rig object's walk and turn and its bones' bob and lean at every frame."""
    hips, spine = rig.pose.bones["hips"], rig.pose.bones["spine"]
    spine.rotation_mode = "XYZ"
    for f, (x, y, heading) in enumerate(walk_path(frames, fps, speed, turn)):
        frame = start + f
        rig.location, rig.rotation_euler = (x, y, 0.0), (0.0, 0.0, heading)
        rig.keyframe_insert("location", frame=frame)
        rig.keyframe_insert("rotation_euler", frame=frame)
        stride = min(f / (0.6 * fps), 1.0)  # the walk's bob and lean grow as it speeds up
        hips.location = (0.0, 0.015 * stride * math.sin(2 * math.pi * 1.8 * f / fps), 0.0)
        spine.rotation_euler = (-math.radians(6.0) * stride, 0.0, 0.0)  # lean forward
        hips.keyframe_insert("location", frame=frame)
        spine.keyframe_insert("rotation_euler", frame=frame)


def build(*, fps: int = 24, start: int = 1, frames: int = 60, key_frame: int = 24,
          flare: float = 12.0, cols: int = 8, rows: int = 11, speed: float = 1.0,
          turn: float = 60.0) -> dict:
    """The example in the current (emptied) scene; its objects by name."""
    scene = bpy.context.scene
    for obj in list(bpy.data.objects):
        bpy.data.objects.remove(obj)
    scene.render.fps, scene.render.fps_base = fps, 1.0
    scene.frame_start, scene.frame_end = start, start + frames - 1
    scene.frame_set(start)
    rig = make_rig(scene)
    character = make_character(scene, rig)
    cape = make_cape(scene, rig, cols, rows)
    add_target(cape, key_frame, flare)
    animate(rig, start, frames, fps, speed, turn)
    scene.frame_set(start)
    bpy.context.view_layer.objects.active = cape
    cape.select_set(True)
    return {"rig": rig, "character": character, "cape": cape}


if __name__ == "__main__":
    args = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []
    build()
    if args:
        bpy.ops.wm.save_as_mainfile(filepath=args[0])
        print(f"rigged_cape: saved {args[0]}")
