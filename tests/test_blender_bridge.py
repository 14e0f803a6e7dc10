"""The Blender add-on's bpy-free half (blender/casadi_keyframe_blender/bridge.py), without
Blender: the command line it runs, its OBJ files read back by the library in the same
vertex order, its PC2 files against the library's reader, the local-space transform, the
progress lines and the misses it shows.  The add-on itself runs in ``make test-blender``."""
import importlib.util
import json
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest

from casadi_keyframe.cli import build_parser
from casadi_keyframe.cli.values import parse_overrides
from casadi_keyframe.export.pc2 import read_pc2
from casadi_keyframe.meshes import read_mesh

PATH = Path(__file__).resolve().parents[1] / "blender" / "casadi_keyframe_blender" / "bridge.py"
spec = importlib.util.spec_from_file_location("ckf_bridge", PATH)
bridge = importlib.util.module_from_spec(spec)
spec.loader.exec_module(bridge)


def test_the_command_parses_as_the_cli_reads_it(tmp_path):
    cmd = bridge.solve_command("/env/bin/casadi-keyframe", cloth=tmp_path / "c.obj",
                               targets=[(80, tmp_path / "b.obj"), (40, tmp_path / "a.obj")],
                               pins=[5], dt=bridge.fps_fraction(30, 1.0), steps=80,
                               out=tmp_path / "r", maxiter=7)
    assert cmd[0] == "/env/bin/casadi-keyframe"
    args = build_parser().parse_args(cmd[1:])
    sets = parse_overrides(args.set)
    assert sets == {"cloth": str(tmp_path / "c.obj"), "dt": 1 / 30, "steps": 80, "pins": (5,),
                    "keyframes": f"40:{tmp_path / 'a.obj'},80:{tmp_path / 'b.obj'}"}
    assert args.maxiter == 7 and args.export == ["pc2"] and args.out == str(tmp_path / "r")
    assert Fraction(bridge.fps_fraction(30, 1.001)) == Fraction(1001, 30000)


def test_obj_text_keeps_vertex_order_and_polygons(tmp_path):
    vertices = [(0.0, 0.0, 0.0), (1.0, 0.0, 0.0), (1.0, 0.0, -1.0), (0.0, 0.0, -1.0),
                (0.1234567890123, 0.5, 0.25)]
    path = tmp_path / "m.obj"
    path.write_text(bridge.obj_text(vertices, [[0, 3, 2, 1], [1, 2, 4]], "test"))
    mesh = read_mesh(path)
    np.testing.assert_array_equal(mesh.vertices, vertices)  # repr: every digit kept
    assert mesh.same_topology([[0, 3, 2], [0, 2, 1], [1, 2, 4]])


def test_pc2_round_trip_and_local_space(tmp_path):
    frames = [[(1.0, 2.0, 3.0), (4.0, 5.0, 6.0)], [(0.5, 0.25, 0.0), (-1.0, 0.0, 2.0)]]
    shift = [[1, 0, 0, -1.0], [0, 0, -1, 0.0], [0, 1, 0, 2.0], [0, 0, 0, 1.0]]
    local = bridge.to_local(frames, shift)
    path = bridge.write_pc2(tmp_path / "a.pc2", local)
    positions, start, rate = read_pc2(path)
    want = np.array(frames) @ np.array(shift)[:3, :3].T + np.array(shift)[:3, 3]
    np.testing.assert_allclose(positions, want, rtol=0, atol=1e-6)
    again, start2, rate2 = bridge.read_pc2(path)
    np.testing.assert_allclose(again, positions) and (start, rate) == (start2, rate2) == (0, 1)


def test_progress_lines_and_targets_by_name():
    lines, rest = bridge.progress_lines("it 1\rit 2\rit", "")
    assert lines == ["it 1", "it 2"] and rest == "it"
    lines, rest = bridge.progress_lines(" 3\ndone\n", rest)
    assert lines == ["it 3", "done"] and rest == ""
    assert bridge.frame_from_name("wave@40") == 40 and bridge.frame_from_name("fold @ 8") == 8
    assert bridge.frame_from_name("Basis") is None and bridge.frame_from_name("a@b") is None


def test_misses_described_with_scene_frames(tmp_path):
    misses = [{"term": "MeshKeyframe@40", "particles": 9, "rms_position_error": 0.004,
               "max_position_error": 0.01},
              {"term": "MeshKeyframe@80", "particles": 9, "rms_position_error": 0.02,
               "max_position_error": 0.05}]
    (tmp_path / "summary.json").write_text(json.dumps({"breakdown": {"misses": misses}}))
    lines = bridge.describe_misses(bridge.read_misses(tmp_path), 0.01, start_frame=1)
    assert lines == ["frame 41: 4.0 mm rms, 10.0 mm max: hit (tolerance 10 mm)",
                     "frame 81: 20.0 mm rms, 50.0 mm max: MISSED (tolerance 10 mm)"]


def test_colliders_are_written_as_the_library_reads_bodies(tmp_path):
    import pytest
    pytest.importorskip("igl")
    from casadi_keyframe.models import MeshBody
    square = [(0.0, 0.0, 0.0), (1.0, 0.0, 0.0), (1.0, 1.0, 0.0), (0.0, 1.0, 0.5)]
    still = bridge.write_body(tmp_path, "floor", [square, square], [[0, 1, 2, 3]])
    assert still.name == "floor.obj" and not MeshBody.from_file(still).moves
    rising = [[(x, y, z + 0.1 * k) for x, y, z in square] for k in range(3)]
    moving = bridge.write_body(tmp_path, "lift", rising, [[0, 1, 2, 3]])
    assert moving.name == "lift.pc2" and (tmp_path / "lift_rest.obj").is_file()
    body = MeshBody.from_file(moving, fps=30)
    np.testing.assert_allclose(body.world_vertices(1 / 60), np.array(square) + [0, 0, 0.05],
                               atol=1e-6)
    cmd = bridge.solve_command("ckf", cloth="c.obj", targets=[(4, "t.obj")], pins=[],
                               dt="1/30", steps=4, out="r", bodies=[still, moving])
    assert parse_overrides(build_parser().parse_args(cmd[1:]).set)["bodies"] == \
        f"{still},{moving}"


def test_pin_motion_written_only_when_a_pin_moves_and_read_as_the_cli_reads_it(tmp_path):
    from casadi_keyframe.meshes import read_animated
    square = [(0.0, 0.0, 0.0), (1.0, 0.0, 0.0), (1.0, 1.0, 0.0), (0.0, 1.0, 0.0)]
    swaying = [[(x + (0.01 * k if i >= 2 else 0.0), y, z) for i, (x, y, z) in enumerate(square)]
               for k in range(4)]
    assert not bridge.pins_move(swaying, [0, 1])  # only the free vertices move
    assert bridge.pins_move(swaying, [2]) and not bridge.pins_move(swaying, [2], 0.05)
    path = bridge.write_motion(tmp_path, "pin_motion", swaying, [[0, 1, 2, 3]])
    assert path.name == "pin_motion.pc2" and (tmp_path / "pin_motion_rest.obj").is_file()
    found = read_animated(path, fps=30)
    np.testing.assert_allclose(found.frames, swaying, atol=1e-7)
    np.testing.assert_allclose(found.mesh.vertices, swaying[0], atol=0)


def test_resolve_and_pin_motion_command_parses_as_the_cli_reads_it(tmp_path):
    cmd = bridge.solve_command("ckf", cloth="c.obj", targets=[(40, "t.obj")], pins=[0, 1],
                               dt="1/24", steps=40, out="r2", pin_motion=tmp_path / "p.pc2",
                               resume=tmp_path / "r", from_frame=25)
    args = build_parser().parse_args(cmd[1:])
    assert parse_overrides(args.set)["pin_motion"] == str(tmp_path / "p.pc2")
    assert args.resume == str(tmp_path / "r") and args.from_frame == 25


def test_time_left_counted_down_from_the_progress_line():
    line = "mesh_keyframes [lbfgsb] 3/30 iterations > simulating 21/39 steps; 47 s in, " \
           "at most 7 min 6 s left"
    assert bridge.time_left(line) == ("at most", 426.0)
    assert bridge.time_left("x; 2 h 5 min in, about 1 h 5 min left") == ("about", 3900.0)
    assert bridge.time_left("stage 0: 4 iterations") is None
    assert bridge.status_text(line, 6.0) == f"at most 7 min 0 s left | {line}"
    assert bridge.status_text("writing result", 3.0) == "writing result"
    from casadi_keyframe.progress import format_seconds
    for s in (0, 45, 89, 90, 200, 3599, 3600, 4000):
        assert bridge.format_seconds(s) == format_seconds(s)


def test_cache_made_local_frame_by_frame():
    frames = [[(1.0, 0.0, 0.0)], [(2.0, 0.0, 0.0)]]
    shift = [[[1, 0, 0, -x], [0, 1, 0, 0.0], [0, 0, 1, 0.0], [0, 0, 0, 1.0]] for x in (1.0, 2.0)]
    assert bridge.to_local(frames, shift) == [[(0.0, 0.0, 0.0)], [(0.0, 0.0, 0.0)]]
    with pytest.raises(ValueError, match="1 transforms for 2 frames"):
        bridge.to_local(frames, shift[:1])
