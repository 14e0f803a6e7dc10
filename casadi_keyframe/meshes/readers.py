"""Mesh files in: OBJ and PLY through trimesh, USD through usd-core.

Each reader returns the file's vertices in the file's order (the order a point cache for the
mesh must keep), its polygons before triangulation and its named vertex sets, and
:func:`.checks.check_mesh` makes them a checked :class:`~.mesh.Mesh`.  Named vertex sets come
from PLY vertex properties (a ``pins`` column, say: the vertices where it is non-zero) and
from USD ``GeomSubset`` s of points and scalar vertex primvars; OBJ has none (its groups are
groups of faces).
"""
from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np

from .checks import MeshError, check_mesh
from .mesh import Mesh

FORMATS = {".obj": "OBJ", ".ply": "PLY", ".usd": "USD", ".usda": "USD", ".usdc": "USD",
           ".usdz": "USD"}
# PLY vertex properties that are geometry or appearance, not a named vertex set
_PLY_STANDARD = {"x", "y", "z", "nx", "ny", "nz", "red", "green", "blue", "alpha", "s", "t",
                 "u", "v", "texture_u", "texture_v", "quality", "intensity"}


def read_mesh(path, role: str = "cloth") -> Mesh:
    """The checked triangle mesh in the file ``path`` (``.obj``, ``.ply``, ``.usd``,
    ``.usda``, ``.usdc``, ``.usdz``); a :class:`MeshError` (a ValueError) naming the file
    when it is missing, unreadable or not a usable mesh for its ``role`` ("cloth", a target
    shape of one, or "body")."""
    path = Path(path)
    if path.is_dir():
        raise MeshError(f"{path}: is a folder, not a mesh file; give the {role}'s file in it "
                        f"(OBJ, PLY or USD)")
    kind = FORMATS.get(path.suffix.lower())
    if kind is None:
        raise MeshError(f"{path}: unknown mesh format {path.suffix or '(no suffix)'!r}; give "
                        f"an OBJ, PLY or USD file ({', '.join(FORMATS)})")
    if not path.is_file():
        raise MeshError(f"{path}: no such file" if not path.exists()
                        else f"{path}: is not a regular file")
    if path.stat().st_size == 0:
        raise MeshError(f"{path}: is empty (0 bytes); export the {role} into it again as a "
                        f"mesh with its faces")
    reader = {"OBJ": _read_obj, "PLY": _read_ply, "USD": _read_usd}[kind]
    vertices, polygons, groups, notices, *numbering = reader(path, role)
    mesh = check_mesh(vertices, polygons, source=path, groups=groups, role=role,
                      **(numbering[0] if numbering else {}))
    if notices:
        mesh = Mesh(mesh.vertices, mesh.faces, mesh.groups, mesh.source,
                    tuple(notices) + mesh.notices)
    return mesh


def _trimesh(path: Path, kind: str, role: str = "cloth"):
    """trimesh's reading of ``path`` with the file's vertex order kept (no merging)."""
    try:
        import trimesh
    except ImportError:
        raise ImportError("reading OBJ and PLY meshes needs trimesh: pip install "
                          "casadi_keyframe[meshes] (or pip install trimesh)") from None
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            loaded = trimesh.load(str(path), file_type=kind.lower(), process=False,
                                  maintain_order=True, force="mesh")
    except Exception as err:  # trimesh raises many kinds for a broken file
        raise MeshError(f"{path}: cannot be read as {kind}: {err}") from None
    if not hasattr(loaded, "vertices") or len(loaded.vertices) == 0:
        raise MeshError(f"{path}: holds no mesh vertices readable as {kind}; export the "
                        f"{role} as a mesh with its faces")
    return loaded


def _read_obj(path: Path, role: str = "cloth"):
    head = path.read_bytes()[:1 << 16]
    try:
        if b"\0" in head:
            raise UnicodeDecodeError("utf-8", head, 0, 1, "NUL byte")
        head.decode("utf-8", errors="strict" if len(head) < 1 << 16 else "ignore")
    except UnicodeDecodeError:
        raise MeshError(f"{path}: cannot be read as OBJ: it is not a text file (an OBJ is "
                        f"text: export it again as Wavefront OBJ)") from None
    sizes, count = _obj_faces(path)
    loaded = _trimesh(path, "OBJ", role)
    if len(loaded.vertices) != count:
        raise MeshError(f"{path}: {count} 'v' lines but {len(loaded.vertices)} vertices read; "
                        f"the vertex order could not be kept (one object per file, please)")
    numbering = {"first": 1, "face_of": np.repeat(np.arange(len(sizes)),
                                                  [max(k - 2, 1) for k in sizes])}
    return (np.asarray(loaded.vertices, float), np.asarray(loaded.faces), {},
            _quads(path, sizes), numbering)


def _obj_faces(path: Path) -> tuple[list[int], int]:
    """``(each face's corner count, the vertex count)`` of an OBJ file, every face's vertex
    numbers checked as the file writes them (from 1, or negative: counted back)."""
    sizes, count, faces = [], 0, []
    with open(path, errors="replace") as f:
        for number, line in enumerate(f, 1):
            if line.startswith("v "):
                count += 1
            elif line.startswith("f "):
                corners = [c.split("/")[0] for c in line.split()[1:]]
                sizes.append(len(corners))
                faces.append((number, len(sizes), count, corners))
    for number, face, seen, corners in faces:
        for corner in corners:
            try:
                i = int(corner)
            except ValueError:
                raise MeshError(f"{path}: line {number}: face {face} has the corner "
                                f"{corner!r}, not a vertex number") from None
            if i == 0 or i > count or -i > seen:
                why = ("OBJ numbers vertices from 1" if i == 0 else
                       f"the file has {count} vertices (1..{count})" if i > 0 else
                       f"only {seen} vertices come before it")
                raise MeshError(f"{path}: line {number}: face {face} uses vertex {i}, but "
                                f"{why}; export the mesh again")
    return sizes, count


def _quads(path, sizes) -> list[str]:
    big = sum(s > 3 for s in sizes)
    return ([f"{path}: {big} of {len(sizes)} faces had more than 3 corners and were split "
             f"into triangles from their first corner"] if big else [])


def _read_ply(path: Path, role: str = "cloth"):
    loaded = _trimesh(path, "PLY", role)
    raw = loaded.metadata.get("_ply_raw", {})
    polygons = raw.get("face", {}).get("data", {}).get("vertex_indices")
    notices = []
    if polygons is not None:
        polygons = [np.asarray(p).ravel() for p in polygons]
        notices = _quads(path, [len(p) for p in polygons])
    else:
        polygons = np.asarray(loaded.faces)
    columns = raw.get("vertex", {}).get("data", {})
    n = len(loaded.vertices)
    groups = {name: np.flatnonzero(np.asarray(values).ravel() != 0)
              for name, values in columns.items()
              if name not in _PLY_STANDARD and np.asarray(values).size == n}  # scalar columns
    return np.asarray(loaded.vertices, float), polygons, groups, notices


def _read_usd(path: Path, role: str = "cloth"):
    try:
        from pxr import Usd, UsdGeom
    except ImportError:
        raise ImportError("reading USD meshes needs usd-core: pip install "
                          "casadi_keyframe[usd] (or pip install usd-core)") from None
    stage, prim = _usd_mesh(path)
    time = Usd.TimeCode.EarliestTime()
    mesh = UsdGeom.Mesh(prim)
    points, turned = _usd_points(stage, prim, time)
    notices = ([f"{path}: the stage is y up; turned to z up as the {role} is simulated"]
               if turned else [])
    counts = np.asarray(mesh.GetFaceVertexCountsAttr().Get(time) or [], int)
    flat = np.asarray(mesh.GetFaceVertexIndicesAttr().Get(time) or [], int)
    if counts.sum() != flat.size:
        raise MeshError(f"{path}: {prim.GetPath()}'s face counts add up to {counts.sum()}, "
                        f"its face indices are {flat.size}")
    polygons = np.split(flat, np.cumsum(counts)[:-1]) if counts.size else []
    return points, polygons, _usd_groups(prim, len(points)), notices + _quads(path, counts)


def _usd_mesh(path: Path):
    """``(stage, prim)``: the stage in ``path`` and its one mesh."""
    from pxr import Usd, UsdGeom
    stage = Usd.Stage.Open(str(path)) if _opens(path) else None
    if stage is None:
        raise MeshError(f"{path}: cannot be read as USD")
    meshes = [p for p in stage.Traverse() if p.IsA(UsdGeom.Mesh)]
    if len(meshes) != 1:
        raise MeshError(f"{path}: holds {len(meshes)} meshes; give a file with exactly one "
                        f"(the cloth, one target shape or one body)" + (
                            f": {', '.join(str(p.GetPath()) for p in meshes[:4])}"
                            if meshes else ""))
    return stage, meshes[0]


def _usd_points(stage, prim, time) -> tuple[np.ndarray, bool]:
    """``(points, turned)``: the mesh's points at ``time`` in the world, in metres, z up
    (``turned``: the stage was y up)."""
    from pxr import UsdGeom
    points = np.asarray(UsdGeom.Mesh(prim).GetPointsAttr().Get(time), float).reshape(-1, 3)
    world = np.asarray(UsdGeom.Xformable(prim).ComputeLocalToWorldTransform(time))
    points = points @ world[:3, :3] + world[3, :3]  # USD matrices act on row vectors
    if UsdGeom.StageHasAuthoredMetersPerUnit(stage):  # unauthored, USD says cm: trust metres
        points *= UsdGeom.GetStageMetersPerUnit(stage)
    turned = (stage.HasAuthoredMetadata("upAxis")
              and UsdGeom.GetStageUpAxis(stage) == UsdGeom.Tokens.y)
    if turned:
        points = np.c_[points[:, 0], -points[:, 2], points[:, 1]]
    return points, turned


def usd_frames(path) -> tuple[np.ndarray, np.ndarray] | None:
    """``(times (k,) s from the first sample, points (k, v, 3))`` of the one mesh of a USD
    file whose points or own transform are time-sampled (None if neither is): each sample
    placed as :func:`read_mesh` places the first (world, metres, z up)."""
    from pxr import UsdGeom
    stage, prim = _usd_mesh(Path(path))
    codes = set(UsdGeom.Mesh(prim).GetPointsAttr().GetTimeSamples())
    for op in UsdGeom.Xformable(prim).GetOrderedXformOps():
        codes |= set(op.GetAttr().GetTimeSamples())
    if len(codes) < 2:
        return None
    codes = sorted(codes)
    _check_topology(path, prim, codes)
    frames = np.array([_usd_points(stage, prim, code)[0] for code in codes])
    return (np.asarray(codes) - codes[0]) / stage.GetTimeCodesPerSecond(), frames


def _check_topology(path, prim, codes) -> None:
    """Refuse (MeshError) a mesh whose points' count or faces change over ``codes``: a
    point cache needs one topology (a rig that adds or removes geometry over time)."""
    from pxr import UsdGeom
    mesh = UsdGeom.Mesh(prim)

    def topology(code):
        return (len(mesh.GetPointsAttr().Get(code) or []),
                tuple(mesh.GetFaceVertexCountsAttr().Get(code) or []),
                tuple(mesh.GetFaceVertexIndicesAttr().Get(code) or []))

    codes = sorted(set(codes) | set(mesh.GetFaceVertexCountsAttr().GetTimeSamples())
                   | set(mesh.GetFaceVertexIndicesAttr().GetTimeSamples()))
    first = topology(codes[0])
    for code in codes[1:]:
        now = topology(code)
        if now != first:
            what = ("points" if now[0] != first[0] else "faces")
            raise MeshError(f"{path}: the mesh's topology changes over time: at time code "
                            f"{code:g} its {what} differ from those at {codes[0]:g} ({now[0]} "
                            f"points, {len(now[1])} faces; first {first[0]} points, "
                            f"{len(first[1])} faces): export a mesh whose vertices and faces "
                            "stay the same at every frame (apply modifiers that add or remove "
                            "geometry, or bake a point cache of a fixed mesh)")


def _opens(path: Path) -> bool:
    from pxr import Sdf
    try:
        return Sdf.Layer.FindOrOpen(str(path)) is not None
    except Exception:  # pxr's Tf errors for a file that is not USD
        return False


def _usd_groups(prim, n: int) -> dict:
    """Point subsets and scalar per-vertex primvars (non-zero values) of a mesh prim."""
    from pxr import UsdGeom
    groups = {}
    for subset in UsdGeom.Subset.GetAllGeomSubsets(UsdGeom.Imageable(prim)):
        if subset.GetElementTypeAttr().Get() == "point":
            groups[subset.GetPrim().GetName()] = np.unique(np.asarray(
                subset.GetIndicesAttr().Get() or [], int))
    for primvar in UsdGeom.PrimvarsAPI(prim).GetPrimvars():
        if primvar.GetInterpolation() not in (UsdGeom.Tokens.vertex, UsdGeom.Tokens.varying):
            continue
        values = primvar.Get()
        if values is None:
            continue
        values = np.asarray(values)
        if values.shape == (n,) and values.dtype.kind in "biuf":
            groups.setdefault(primvar.GetPrimvarName(), np.flatnonzero(values != 0))
    return groups
