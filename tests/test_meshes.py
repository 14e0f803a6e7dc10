"""Meshes in: OBJ, PLY and USD read in the file's vertex order, the checks' refusals, pins
by index, vertex set and box, and ClothModel.from_file against from_mesh."""
import numpy as np
import pytest

from casadi_keyframe.meshes import MeshError, PinBox, pin_indices, read_mesh
from casadi_keyframe.models import ClothModel
from casadi_keyframe.scenes.mesh_targets import fold, hanging_sheet, wave, write_sheet_and_targets

SQUARE = """v 0 0 0\nv 1 0 0\nv 1 0 -1\nv 0 0 -1\nv 2 0 0\nv 2 0 -1\n"""


def write(tmp_path, name, text):
    path = tmp_path / name
    path.write_text(text)
    return path


def test_obj_keeps_the_file_order_and_fans_quads_with_a_notice(tmp_path):
    # texture and normal indices differ per corner, as Blender writes them
    path = write(tmp_path, "two.obj", SQUARE + "vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nvt .5 .5\n"
                 "vn 0 1 0\nf 1/1/1 4/4/1 3/3/1 2/2/1\nf 2/5/1 3/2/1 6/3/1 5/4/1\n")
    mesh = read_mesh(path)
    np.testing.assert_array_equal(mesh.vertices[[0, 4]], [[0, 0, 0], [2, 0, 0]])
    assert mesh.same_topology([[0, 3, 2], [0, 2, 1], [1, 2, 5], [1, 5, 4]])
    assert not mesh.same_topology([[0, 3, 1], [3, 2, 1], [1, 2, 5], [1, 5, 4]])
    assert len(mesh.notices) == 1 and "2 of 2 faces" in mesh.notices[0]
    tri = read_mesh(write(tmp_path, "tri.obj", SQUARE + "f 1 4 3\nf 1 3 2\nf 2 3 6\nf 2 6 5\n"))
    assert tri.notices == () and tri.same_topology(mesh.faces)


def test_ply_vertex_properties_are_named_sets(tmp_path):
    header = ("ply\nformat ascii 1.0\nelement vertex 6\nproperty float x\nproperty float y\n"
              "property float z\nproperty uchar pins\nelement face 2\n"
              "property list uchar int vertex_indices\nend_header\n")
    rows = "0 0 0 1\n1 0 0 0\n1 0 -1 0\n0 0 -1 0\n2 0 0 1\n2 0 -1 0\n4 0 3 2 1\n4 1 2 5 4\n"
    mesh = read_mesh(write(tmp_path, "s.ply", header + rows))
    assert mesh.n == 6 and mesh.faces.shape == (4, 3)
    np.testing.assert_array_equal(pin_indices(mesh, "pins"), [0, 4])
    with pytest.raises(MeshError, match="no vertex set named 'top'.*pins"):
        pin_indices(mesh, "top")


def test_usd_mesh_with_a_transform_and_a_point_subset(tmp_path):
    from pxr import Gf, Usd, UsdGeom, Vt
    path = tmp_path / "sheet.usda"
    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z)
    xform = UsdGeom.Xform.Define(stage, "/Cloth")
    xform.AddTranslateOp().Set(Gf.Vec3d(0, 0, 2))
    mesh = UsdGeom.Mesh.Define(stage, "/Cloth/Sheet")
    v, quads = hanging_sheet(3, 3)
    mesh.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(v.astype(np.float32)))
    mesh.CreateFaceVertexCountsAttr([4] * len(quads))
    mesh.CreateFaceVertexIndicesAttr(quads.ravel().tolist())
    UsdGeom.Subset.Define(stage, "/Cloth/Sheet/pins").CreateElementTypeAttr("point")
    UsdGeom.Subset(stage.GetPrimAtPath("/Cloth/Sheet/pins")).CreateIndicesAttr([2, 0])
    stage.Save()
    read = read_mesh(path)
    np.testing.assert_allclose(read.vertices, v + [0, 0, 2], atol=1e-6)
    np.testing.assert_array_equal(pin_indices(read, "pins"), [0, 2])
    model = ClothModel.from_file(path, pinned="pins")
    np.testing.assert_array_equal(model.pinned, [0, 2])


FAN = "v 0 0 0\nv 1 0 0\nv 1 0 -1\nv 0 0 -1\nv 0.5 1 -0.5\n"


@pytest.mark.parametrize("text, message", [  # vertices and faces numbered as OBJ counts them
    (FAN + "f 1 2 3\nf 1 2 4\nf 1 2 5\n", "non-manifold: 1 edge.*vertices 1 and 2, in 3"),
    (FAN + "f 1 2 3\nf 1 3 3\nf 1 3 4\nf 3 4 5\n", "repeat a vertex.*face 2 \\(vertices 1 3 3"),
    (FAN + "f 1 2 3\nf 1 3 4\n", "belong to no face.*vertex 5"),
    (FAN + "v 2 0 0\nf 1 2 3\nf 1 3 4\nf 2 3 5\nf 1 2 6\n", "no area.*face 4 \\(vertices 1 2 6"),
    (FAN + "f 1 2 3\nf 1 3 4\nf 3 4 9\n", "line 8: face 3 uses vertex 9, but the file has 5 "
                                          "vertices \\(1..5\\)"),
    (FAN + "f 0 2 3\nf 1 3 4\n", "line 6: face 1 uses vertex 0, but OBJ numbers vertices from 1"),
    (FAN + "f 1 2 -9\n", "line 6: face 1 uses vertex -9, but only 5 vertices come before it"),
])
def test_bad_meshes_are_refused_by_name(tmp_path, text, message):
    with pytest.raises(MeshError, match=message) as err:
        read_mesh(write(tmp_path, "bad.obj", text))
    assert "bad.obj" in str(err.value)


def test_unreadable_and_missing_files(tmp_path):
    with pytest.raises(MeshError, match="no such file"):
        read_mesh(tmp_path / "none.obj")
    with pytest.raises(MeshError, match="unknown mesh format '.stl'"):
        read_mesh(write(tmp_path, "a.stl", "solid"))
    with pytest.raises(MeshError, match="junk.obj"):
        read_mesh(write(tmp_path, "junk.obj", "this is not\x00 a mesh\n"))
    binary = tmp_path / "binary.obj"
    binary.write_bytes(bytes(range(256)) * 8)
    with pytest.raises(MeshError, match="binary.obj: cannot be read as OBJ: it is not a text"):
        read_mesh(binary)
    with pytest.raises(MeshError, match="junk.ply"):
        read_mesh(write(tmp_path, "junk.ply", "ply\nformat nonsense\n"))
    with pytest.raises(MeshError, match="junk.usda: cannot be read as USD"):
        read_mesh(write(tmp_path, "junk.usda", "#usda 1.0\n( what\n"))


def test_pins_by_index_and_box(tmp_path):
    paths = write_sheet_and_targets(tmp_path, 4, 5)
    mesh = read_mesh(paths["sheet"])
    np.testing.assert_array_equal(pin_indices(mesh, [4, 0, 4]), [0, 4])
    np.testing.assert_array_equal(pin_indices(mesh, PinBox((-1, -1, -0.01), (2, 1, 1))),
                                  np.arange(5))
    with pytest.raises(MeshError, match="pinned vertex 20 is out of range.*20 vertices, 0..19"):
        pin_indices(mesh, [0, 20])
    with pytest.raises(MeshError, match="holds no vertex"):
        pin_indices(mesh, PinBox((5, 5, 5), (6, 6, 6)))


def test_from_file_is_from_mesh_of_the_file(tmp_path):
    paths = write_sheet_and_targets(tmp_path, 4, 5)
    model = ClothModel.from_file(paths["sheet"], pinned=[0, 4], mass=0.3)
    v, quads = hanging_sheet(4, 5)
    tris = np.vstack([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]])
    ref = ClothModel.from_mesh(v, tris, pinned=[0, 4], mass=0.3)
    np.testing.assert_allclose(model.rest_positions, ref.rest_positions, atol=1e-7)
    np.testing.assert_allclose(model.masses, ref.masses, rtol=1e-6)
    def pairs(m):
        return set(map(tuple, np.sort(np.c_[m.springs.i, m.springs.j], axis=1).tolist()))
    assert pairs(model) == pairs(ref)
    np.testing.assert_array_equal(model.pinned, [0, 4])


def test_targets_keep_the_cloth_unstretched():
    v, quads = hanging_sheet(12, 12)
    model = ClothModel.from_mesh(v, np.vstack([quads[:, :3], quads[:, [0, 2, 3]]]))
    assert model.max_stretch(fold(v)) < 1.0 + 1e-5  # developable: chords only shorten
    assert model.max_stretch(wave(v)) < 1.3
    assert np.ptp(fold(v)[:, 1]) > 0.3 and np.ptp(wave(v)[:, 1]) > 0.2  # they do move
