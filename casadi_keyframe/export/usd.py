"""One USD stage per result (needs ``usd-core``: ``pip install casadi_keyframe[usd]``).

``/Result`` (the default prim) holds the particles: a cloth as a time-sampled
``UsdGeom.Mesh`` (faces once, points per frame), a flock as a time-sampled
``UsdGeom.PointInstancer`` (positions, orientations along the velocity, ids; ``Agent`` and
``Highlighted`` cone prototypes); ``Colliders`` (moving ones with a time-sampled transform);
``Targets``, one prim per keyframe target, and the view's ``Ring``, each hideable on its
own; for a blend, ``Clips/fall`` and ``Clips/walk`` in their own world positions.  Time code
n is frame n at ``1 / dt`` codes per second, ``metersPerUnit`` 1, z up, as the problems are
built.
"""
from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from ..geometry import Round, basis, circle
from ..interrupts import check
from ..saved import atomic_path
from ..objectives.markers import Outline, Points, WholeShape

INSTALL = "pip install casadi_keyframe[usd]"
CLOTH, CLIP, HIGHLIGHT, AGENT, TARGET, BODY, RING = (
    (0.42, 0.56, 0.78), (0.6, 0.6, 0.65), (0.88, 0.51, 0.17), (0.3, 0.45, 0.69),
    (0.84, 0.15, 0.16), (0.55, 0.55, 0.55), (0.88, 0.51, 0.17))


def pxr_modules():
    """``(Gf, Sdf, Usd, UsdGeom, Vt)`` from usd-core, or an ImportError that says how to
    install it."""
    try:
        from pxr import Gf, Sdf, Usd, UsdGeom, Vt
    except ImportError:
        raise ImportError(f"USD export needs usd-core, which is not installed: "
                          f"{INSTALL} (or pip install usd-core)") from None
    return Gf, Sdf, Usd, UsdGeom, Vt


def frame_rate(dt: float) -> float:
    """``1 / dt``, rounded to a whole number when it is one to round-off (1/60 -> 60)."""
    rate = 1.0 / dt
    return float(round(rate)) if abs(rate - round(rate)) < 1e-9 * rate else rate


def prim_name(text: str) -> str:
    """A valid prim name from a label (``"CenterOfMass@32"`` -> ``"CenterOfMass_32"``)."""
    name = re.sub(r"\W", "_", text)
    return name if name[:1].isalpha() or name[:1] == "_" else f"_{name}"


def write_usd(scene, path) -> Path:
    """Write ``scene`` (:class:`.scene.Scene`) as a USD stage at ``path`` (``.usd``,
    ``.usda`` or ``.usdc``), whole or not at all."""
    _, Sdf, Usd, UsdGeom, _ = pxr_modules()
    layer = Sdf.Layer.CreateAnonymous(Path(path).suffix)
    stage = Usd.Stage.Open(layer)
    rate = frame_rate(scene.dt)
    stage.SetStartTimeCode(0)
    stage.SetEndTimeCode(scene.frames - 1)
    stage.SetTimeCodesPerSecond(rate)
    stage.SetFramesPerSecond(rate)
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z)
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    root = UsdGeom.Xform.Define(stage, "/Result").GetPrim()
    stage.SetDefaultPrim(root)
    layer.documentation = (f"{scene.name}: a result of casadi_keyframe; time code n is frame "
                           f"n, dt = {scene.dt:.9g} s; metres, z up")
    writer = _Writer(stage, scene)
    writer.particles("/Result/" + ("Cloth" if scene.faces is not None else "Flock"))
    writer.colliders("/Result/Colliders", scene.bodies)
    writer.targets("/Result/Targets")
    for clip in scene.clips:
        writer.mesh(f"/Result/Clips/{clip.name}/Cape", clip.positions, CLIP)
        writer.colliders(f"/Result/Clips/{clip.name}/Colliders", clip.bodies)
    with atomic_path(path) as tmp:
        layer.Export(str(tmp))
    return Path(path)


class _Writer:
    """Defines the prims of one scene on one stage."""

    def __init__(self, stage, scene):
        self.Gf, self.Sdf, self.Usd, self.UsdGeom, self.Vt = pxr_modules()
        self.stage, self.scene = stage, scene
        pts = [scene.positions.reshape(-1, 3)] + [t.points for t in scene.targets]
        lo, hi = np.min([p.min(0) for p in pts], 0), np.max([p.max(0) for p in pts], 0)
        self.mid, self.half = (lo + hi) / 2, 0.6 * max((hi - lo).max(), 1.0)

    def _vec3(self, x):
        return self.Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(x, dtype=np.float32))

    def _extent(self, x, pad: float = 0.0):
        x = np.asarray(x, dtype=np.float32)
        return self._vec3(np.array([x.min(0) - pad, x.max(0) + pad]))

    def _points_over_time(self, geom, positions, pad: float = 0.0):
        """Author ``points`` and ``extent`` at every frame (one value if there is one)."""
        points, extent = geom.CreatePointsAttr(), geom.CreateExtentAttr()
        if len(positions) == 1:
            points.Set(self._vec3(positions[0]))
            extent.Set(self._extent(positions[0], pad))
            return
        for n, x in enumerate(positions):
            check()
            points.Set(self._vec3(x), float(n))
            extent.Set(self._extent(x, pad), float(n))

    def _color(self, geom, rgb):
        geom.CreateDisplayColorAttr(self.Vt.Vec3fArray([self.Gf.Vec3f(*rgb)]))

    def mesh(self, path, positions, rgb, faces=None):
        """A triangle mesh with ``positions`` per frame (``(frames, n, 3)``)."""
        UsdGeom = self.UsdGeom
        mesh = UsdGeom.Mesh.Define(self.stage, path)
        faces = self.scene.faces if faces is None else np.asarray(faces)
        mesh.CreateFaceVertexCountsAttr(self.Vt.IntArray([faces.shape[1]] * len(faces)))
        mesh.CreateFaceVertexIndicesAttr(self.Vt.IntArray(faces.ravel().tolist()))
        mesh.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
        mesh.CreateDoubleSidedAttr(True)
        self._points_over_time(mesh, positions)
        self._color(mesh, rgb)
        return mesh

    def points(self, path, positions, rgb, width: float):
        """A points prim with ``positions`` per frame and a constant ``width``."""
        pts = self.UsdGeom.Points.Define(self.stage, path)
        pts.CreateWidthsAttr(self.Vt.FloatArray([width]))
        pts.SetWidthsInterpolation(self.UsdGeom.Tokens.constant)
        self._points_over_time(pts, positions, pad=width / 2)
        self._color(pts, rgb)
        return pts

    def particles(self, path):
        """The cloth's mesh, or the flock's point instancer."""
        if self.scene.faces is not None:
            self.mesh(path, self.scene.positions, CLOTH)
        else:
            self.instancer(path)

    def instancer(self, path, length: float = 0.4):
        """The flock as a ``PointInstancer``: per frame the agents' positions, orientations
        (the cone's +x turned onto the velocity) and velocities; ``ids`` and prototype
        indices (1 for a highlighted agent) once."""
        scene, UsdGeom, Vt = self.scene, self.UsdGeom, self.Vt
        n = scene.positions.shape[1]
        inst = UsdGeom.PointInstancer.Define(self.stage, path)
        protos = [self.cone(f"{path}/Prototypes/Agent", length, AGENT),
                  self.cone(f"{path}/Prototypes/Highlighted", 1.5 * length, HIGHLIGHT)]
        inst.CreatePrototypesRel().SetTargets([p.GetPath() for p in protos])
        index = np.zeros(n, dtype=np.int32)
        index[list(scene.highlight)] = 1
        inst.CreateProtoIndicesAttr(Vt.IntArray(index.tolist()))
        inst.CreateIdsAttr(Vt.Int64Array(list(range(n))))
        positions, orientations = inst.CreatePositionsAttr(), inst.CreateOrientationsAttr()
        velocities, extent = inst.CreateVelocitiesAttr(), inst.CreateExtentAttr()
        v = np.zeros_like(scene.positions) if scene.velocities is None else scene.velocities
        for k, (x, vk) in enumerate(zip(scene.positions, v)):
            check()
            positions.Set(self._vec3(x), float(k))
            velocities.Set(self._vec3(vk), float(k))
            q = heading_quaternions(vk)[:, [1, 2, 3, 0]]  # GfQuath's memory: i, j, k, real
            orientations.Set(Vt.QuathArray.FromNumpy(q.astype(np.float16)), float(k))
            extent.Set(self._extent(x, 0.75 * length), float(k))
        return inst

    def cone(self, path, length: float, rgb):
        """A cone along +x, ``length`` long, its apex forward (an agent's shape)."""
        cone = self.UsdGeom.Cone.Define(self.stage, path)
        cone.CreateAxisAttr(self.UsdGeom.Tokens.x)
        cone.CreateHeightAttr(length)
        cone.CreateRadiusAttr(length / 3)
        half = np.array([length / 2, length / 3, length / 3])
        cone.CreateExtentAttr(self._vec3(np.array([-half, half])))
        self._color(cone, rgb)
        return cone

    def colliders(self, path, bodies):
        """One prim per collider under ``path``: by its shape's writer in :data:`SHAPES`,
        else as a mesh of its polygons."""
        if not bodies:
            return
        self.UsdGeom.Scope.Define(self.stage, path)
        for body in bodies:
            SHAPES.get(type(body.shape), _Writer.polygons)(self, f"{path}/{prim_name(body.name)}",
                                                          body)

    def polygons(self, path, body):
        """A body as a mesh of its shape's polygons (:meth:`~..geometry.BodyShape.polygons`;
        a plane's patch below the stage's middle), time-sampled if it moves."""
        surfaces = [shape.polygons(self.mid, self.half) for shape in body.frames()]
        self.mesh(path, np.array([v for v, _ in surfaces]), BODY, faces=surfaces[0][1])

    def round(self, path, body):
        """A sphere, or a capsule along z placed by a transform from ``a`` to ``b``."""
        Gf, UsdGeom = self.Gf, self.UsdGeom
        sphere = body.shape.sphere
        if sphere:
            prim = UsdGeom.Sphere.Define(self.stage, path)
        else:
            prim = UsdGeom.Capsule.Define(self.stage, path)
            prim.CreateAxisAttr(UsdGeom.Tokens.z)
        op = prim.AddTransformOp()
        for n, shape in enumerate(body.frames()):
            a, b, r = shape.a, shape.b, float(shape.radius)
            axis, e1, e2 = basis(b - a)
            if sphere:
                axis, e1, e2 = np.eye(3)[2], np.eye(3)[0], np.eye(3)[1]
            matrix = Gf.Matrix4d(*np.r_[e1, 0, e2, 0, axis, 0, (a + b) / 2, 1].tolist())
            length = float(np.linalg.norm(b - a))
            time = float(n) if body.moving else self.Usd.TimeCode.Default()
            op.Set(matrix, time)
            prim.GetRadiusAttr().Set(r, time)
            half = np.array([r, r, r + (0 if sphere else length / 2)])
            prim.CreateExtentAttr().Set(self._vec3(np.array([-half, half])), time)
            if not sphere:
                prim.GetHeightAttr().Set(length, time)
        self._color(prim, BODY)

    def targets(self, path):
        """Each keyframe target, and the view's ring, as its own prim under ``path``."""
        scene = self.scene
        if not scene.targets and scene.ring is None:
            return
        self.UsdGeom.Scope.Define(self.stage, path)
        for t in scene.targets:
            prim = TARGET_PRIMS[t.figure](self, f"{path}/{prim_name(t.label)}", t.points)
            prim.GetPrim().SetCustomDataByKey("keyframe_frame", int(t.frame))
        if scene.ring is not None:
            ring = scene.ring
            self.curve(f"{path}/Ring", circle(ring.center, ring.normal, ring.radius)[:-1], RING,
                       width=0.03)

    def curve(self, path, points, rgb, width: float):
        """A closed polyline through ``points`` (``(k, 3)``)."""
        UsdGeom = self.UsdGeom
        points = np.asarray(points, float)
        if np.allclose(points[0], points[-1]):
            points = points[:-1]
        curve = UsdGeom.BasisCurves.Define(self.stage, path)
        curve.CreateTypeAttr(UsdGeom.Tokens.linear)
        curve.CreateWrapAttr(UsdGeom.Tokens.periodic)
        curve.CreateCurveVertexCountsAttr(self.Vt.IntArray([len(points)]))
        curve.CreateWidthsAttr(self.Vt.FloatArray([width]))
        curve.SetWidthsInterpolation(UsdGeom.Tokens.constant)
        self._points_over_time(curve, points[None], pad=width / 2)
        self._color(curve, rgb)
        return curve


# a shape's own prim where USD has one (else its polygons as a mesh: _Writer.polygons)
SHAPES = {Round: _Writer.round}
# the prim of each figure of a keyframe target (objectives.markers.Figure), from its points
TARGET_PRIMS = {WholeShape: lambda w, path, p: w.mesh(path, p[None], TARGET),
                Points: lambda w, path, p: w.points(path, p[None], TARGET, width=0.05),
                Outline: lambda w, path, p: w.curve(path, p, TARGET, width=0.05)}


def heading_quaternions(velocities) -> np.ndarray:
    """``(n, 4)`` unit quaternions (real part first, USD's ``quath`` order) that turn +x onto
    each velocity's direction by the shortest arc; no turn where the velocity is 0, half a
    turn about z where it points along -x."""
    v = np.asarray(velocities, float)
    speed = np.linalg.norm(v, axis=1, keepdims=True)
    u = np.divide(v, speed, out=np.tile([1.0, 0.0, 0.0], (len(v), 1)), where=speed > 1e-12)
    q = np.c_[1.0 + u[:, 0], np.zeros(len(u)), -u[:, 2], u[:, 1]]  # (1 + x.u, x cross u)
    back = q[:, 0] < 1e-9
    q[back] = [0.0, 0.0, 0.0, 1.0]
    return q / np.linalg.norm(q, axis=1, keepdims=True)


def validate(path) -> list[str]:
    """USD's own checks of the file at ``path``: the messages of
    ``UsdUtils.ComplianceChecker`` where this usd-core has it, else of every registered
    ``UsdValidation`` validator (its successor, what ``usdchecker`` runs); empty if clean."""
    pxr_modules()
    from pxr import Usd, UsdUtils

    if hasattr(UsdUtils, "ComplianceChecker"):
        checker = UsdUtils.ComplianceChecker()
        checker.CheckCompliance(str(path))
        return [*checker.GetErrors(), *checker.GetFailedChecks()]
    from pxr import UsdValidation

    validators = UsdValidation.ValidationRegistry().GetOrLoadAllValidators()
    errors = UsdValidation.ValidationContext(validators).Validate(Usd.Stage.Open(str(path)))
    return [e.GetErrorAsString() for e in errors]


def write_stage(scene, folder) -> list[Path]:
    """``NAME.usd`` in ``folder`` (the :data:`~casadi_keyframe.export.FORMATS` writer)."""
    return [write_usd(scene, Path(folder) / f"{scene.name}.usd")]
