"""What the add-on reads from the scene for a solve: the cloth as evaluated at the scene's
start, its targets (shape keys named ``NAME@FRAME`` or keyed to 1, and mesh objects named
``NAME@FRAME``), the motion of its pinned vertices (parenting, armature, hooks: the
evaluated mesh per frame) and the bodies of the ``colliders`` collection per frame, all
written as mesh files in world space; and the command that solves them."""
from __future__ import annotations

import contextlib
import shlex
import tempfile
from pathlib import Path

import bpy

from . import bridge

MODIFIER = "casadi_keyframe"  # the Mesh Cache modifier that plays a result
COLLIDERS = "colliders"  # the collection whose mesh objects are bodies
# modifiers that move vertices and keep the mesh's topology: they carry pinned vertices
DEFORMERS = {"ARMATURE", "HOOK", "LATTICE", "CURVE", "MESH_DEFORM", "SURFACE_DEFORM",
             "SIMPLE_DEFORM", "CAST", "WARP", "WAVE", "DISPLACE", "SHRINKWRAP", "SMOOTH",
             "LAPLACIANDEFORM", "CORRECTIVE_SMOOTH"}


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


@contextlib.contextmanager
def shaped(obj, key_index: int = 0):
    """``obj`` evaluated as its rig moves it, in the shape of shape key ``key_index`` alone
    at full value (0: the basis, no target mixed in), without the result's Mesh Cache and
    without the modifiers that change its topology; all restored after the block."""
    hidden = [m for m in obj.modifiers if m.show_viewport and m.type not in DEFORMERS]
    was = (obj.show_only_shape_key, obj.active_shape_key_index)
    try:
        for m in hidden:
            m.show_viewport = False
        if obj.data.shape_keys is not None:
            obj.show_only_shape_key, obj.active_shape_key_index = True, key_index
        yield obj
    finally:
        for m in hidden:
            m.show_viewport = True
        obj.show_only_shape_key, obj.active_shape_key_index = was


def evaluated_points(obj, depsgraph, what: str, frame: int, polygons=None):
    """``(world points, polygons)`` of ``obj`` as evaluated now (the scene at ``frame``);
    a mesh whose faces differ from ``polygons`` is refused, naming ``what`` it is."""
    evaluated = obj.evaluated_get(depsgraph)
    mesh = evaluated.to_mesh()
    try:
        faces = [list(p.vertices) for p in mesh.polygons]
        if polygons is not None and faces != polygons:
            raise ValueError(f"{what} {obj.name} changes its faces at frame {frame}: it must "
                             f"keep its mesh's topology over the shot (a modifier that "
                             f"adds or removes geometry over time, such as Build or "
                             f"Decimate, cannot be followed)")
        return world_points(evaluated.matrix_world, mesh.vertices), faces
    finally:
        evaluated.to_mesh_clear()


def sample_meshes(scene, objects, frames) -> list:
    """``[(per-frame world points, polygons)]`` of each ``(role, object)`` of ``objects``
    evaluated at each of the scene's ``frames``; the scene is put back at its frame."""
    current = scene.frame_current
    points, faces = [[] for _ in objects], [None for _ in objects]
    try:
        for frame in frames:
            scene.frame_set(frame)
            depsgraph = bpy.context.evaluated_depsgraph_get()
            for k, (role, obj) in enumerate(objects):
                found, faces[k] = evaluated_points(obj, depsgraph, role, frame, faces[k])
                points[k].append(found)
    finally:
        scene.frame_set(current)
    return list(zip(points, faces))


def shape_at(obj, scene, key_index: int, frame: int):
    """World points of ``obj`` at ``frame`` in the shape of shape key ``key_index``."""
    with shaped(obj, key_index):
        return sample_meshes(scene, [("cloth", obj)], [frame])[0][0][0]


def collect_targets(obj, scene):
    """``[(scene frame, name, world points)]`` of the object's target shape keys (each as
    its rig places it at its frame) and of the scene's mesh objects named ``NAME@FRAME``."""
    found = []
    keys = obj.data.shape_keys
    if keys is not None:
        for index, block in enumerate(keys.key_blocks):
            if block == keys.reference_key:
                continue
            frame = bridge.frame_from_name(block.name)
            frame = keyed_frame(keys, block) if frame is None else frame
            if frame is not None:
                found.append((frame, block.name, shape_at(obj, scene, index, frame)))
    for other in scene.objects:
        frame = bridge.frame_from_name(other.name)
        if other is obj or other.type != "MESH" or frame is None:
            continue
        if len(other.data.vertices) != len(obj.data.vertices):
            raise ValueError(f"target object {other.name} has {len(other.data.vertices)} "
                             f"vertices, {obj.name} {len(obj.data.vertices)}: a target must be "
                             f"a copy of the cloth in another shape")
        found.append((frame, other.name, world_points(other.matrix_world, other.data.vertices)))
    return sorted(found, key=lambda t: (t[0], t[1]))


def colliders(cloth) -> list:
    """The mesh objects of the ``colliders`` collection, but the ``cloth``."""
    collection = bpy.data.collections.get(COLLIDERS)
    return [o for o in (collection.all_objects if collection else [])
            if o.type == "MESH" and o is not cloth]


def collect_motion(cloth, scene, folder, steps: int, pins):
    """Sample the cloth (its basis shape as its rig moves it) and the colliders at every
    frame from the scene's start over ``steps`` frames and one more; write each collider as
    a body file and, when a pinned vertex moves, the cloth as the pins' motion file.
    Returns ``(cloth's start points, polygons, body files, pin motion file or None)``."""
    bodies = colliders(cloth)
    frames = range(scene.frame_start, scene.frame_start + steps + 2)
    with shaped(cloth):
        (points, polygons), *found = sample_meshes(
            scene, [("cloth", cloth), *(("collider", o) for o in bodies)], frames)
    if len(points[0]) != len(cloth.data.vertices):
        raise ValueError(f"{cloth.name}'s deforming modifiers change its vertex count")
    files = [bridge.write_body(folder, f"collider_{bpy.path.clean_name(o.name)}", *sampled)
             for o, sampled in zip(bodies, found)]
    motion = (bridge.write_motion(folder, "pin_motion", points, polygons)
              if pins and bridge.pins_move(points, pins) else None)
    return points[0], polygons, files, motion


def work_folder(settings, obj) -> Path:
    if settings.folder:
        return Path(bpy.path.abspath(settings.folder))
    if bpy.data.filepath:
        return Path(bpy.path.abspath(f"//casadi_keyframe/{bpy.path.clean_name(obj.name)}"))
    return Path(tempfile.mkdtemp(prefix="casadi_keyframe_"))


def pinned(obj, group_name: str) -> list[int]:
    """The vertices of ``obj``'s vertex group ``group_name`` with a weight above 0."""
    group = obj.vertex_groups.get(group_name)
    return [] if group is None else [v.index for v in obj.data.vertices
                                     if any(g.group == group.index and g.weight > 0
                                            for g in v.groups)]


def solver_options(text: str) -> list[str]:
    """The settings' extra solver options as arguments (quoted as in a shell)."""
    try:
        return shlex.split(text)
    except ValueError as err:
        raise ValueError(f"Solver options: {err} in {text!r}") from None


def prepare(context, executable: str, resume=None, from_frame: int | None = None):
    """Write the cloth, its targets, its pins' motion and the colliders, and return
    ``(command, out folder)``; with ``resume`` (a finished run's folder) the command keeps
    its motion up to result frame ``from_frame`` and solves the rest."""
    obj, scene = context.active_object, context.scene
    settings = scene.casadi_keyframe
    if obj is None or obj.type != "MESH":
        raise ValueError("select the cloth: a mesh object")
    start = scene.frame_start
    targets = [(f - start, name, pts) for f, name, pts in collect_targets(obj, scene)]
    if not targets:
        raise ValueError(f"{obj.name} has no targets: name shape keys NAME@FRAME (or key their "
                         f"value to 1 at a frame)")
    early = [f"{name} at frame {f + start}" for f, name, _ in targets if f < 1]
    if early:
        raise ValueError(f"targets must come after the scene's start frame {start}: "
                         f"{', '.join(early)}")
    pins = pinned(obj, settings.pins_group)
    folder = work_folder(settings, obj)
    folder.mkdir(parents=True, exist_ok=True)
    steps = settings.steps or max(f for f, _, _ in targets)
    rest, polygons, bodies, motion = collect_motion(obj, scene, folder, steps, pins)
    cloth = folder / "cloth.obj"
    cloth.write_text(bridge.obj_text(rest, polygons, f"{obj.name} at the start, world space"))
    files = []
    for frame, name, pts in targets:
        path = folder / f"target_{frame:04d}.obj"
        path.write_text(bridge.obj_text(pts, polygons, f"{name}: result frame {frame}"))
        files.append((frame, path))
    out = folder / ("result" if resume is None else f"result_from_{from_frame:04d}")
    command = bridge.solve_command(
        executable, cloth=cloth, targets=files, pins=pins,
        dt=bridge.fps_fraction(scene.render.fps, scene.render.fps_base), steps=steps,
        out=out, maxiter=settings.maxiter, bodies=bodies, pin_motion=motion, resume=resume,
        from_frame=from_frame, extra=solver_options(settings.options))
    return command, out
