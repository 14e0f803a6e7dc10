"""Meshes in: a cloth and its target shapes read from the files a DCC writes.

:func:`read_mesh` reads OBJ and PLY (through trimesh) and USD (through usd-core) into a
checked triangle :class:`Mesh`: the file's vertices in the file's order (a point cache
written for them plays on the mesh the file came from), quads and larger polygons
triangulated by a fan from their first corner (so two files of the same polygons give the
same triangles whatever their shapes; the mesh carries a notice saying so), and refused with
a :class:`MeshError` naming the file and the fix when a mesh is non-manifold, has degenerate
faces or vertices no face uses.  :func:`pin_indices` turns vertex indices, a named vertex set
or a box into pinned particles.  :func:`read_animated` reads a body's mesh with its per-frame
vertices (USD time samples, a PC2 cache and its rest mesh), checked as a body
(:func:`check_body`: faces wound alike and facing out, an open mesh noted); :mod:`.distance`
finds closest points on it (libigl, the ``bodies`` extra).
"""
from .animation import Animated, read_animated
from .checks import MeshError, check_body, check_mesh, triangulate
from .mesh import Mesh
from .pins import PinBox, pin_indices
from .readers import FORMATS, read_mesh

__all__ = ["Animated", "FORMATS", "Mesh", "MeshError", "PinBox", "check_body", "check_mesh",
           "pin_indices",
           "read_animated", "read_mesh", "triangulate"]
