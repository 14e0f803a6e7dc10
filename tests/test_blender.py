"""A real client: Blender (headless) opens a cloth result's rest OBJ, plays its PC2 through
the Mesh Cache modifier as the README's clicks do, and imports one OBJ of the sequence; the
vertices it sees match result.npz to float32 precision."""
import json
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from casadi_keyframe import cli
from casadi_keyframe.export import export

BLENDER = shutil.which("blender")


@pytest.mark.skipif(BLENDER is None, reason="Blender is not installed (Debian: apt-get install "
                                            "blender); the PC2/OBJ client check needs it")
def test_blender_mesh_cache_plays_the_result(tmp_path):
    out = tmp_path / "toss"
    assert cli.main(["solve", "cloth_toss", "--set", "rows=4", "--set", "cols=5", "--set",
                     "steps=10", "--maxiter", "1", "--quiet", "--no-animation", "--no-viewer",
                     "--out", str(out)]) in (0, 3)
    pc2, rest = export(out, "pc2")
    sequence = export(out, "obj")
    frames = [0, 1, 6, 10]
    dump = tmp_path / "blender.json"
    script = Path(__file__).with_name("blender_mesh_cache.py")
    run = subprocess.run([BLENDER, "-b", "--factory-startup", "--python", str(script), "--",
                          str(rest), str(pc2), str(sequence[7]), str(dump), *map(str, frames)],
                         capture_output=True, text=True, timeout=120)
    print(run.stdout[-2000:])
    assert run.returncode == 0 and dump.is_file(), run.stdout[-2000:] + run.stderr[-2000:]
    seen, x = json.loads(dump.read_text()), np.load(out / "result.npz")["x"]
    for n in frames:  # float32 positions, read back by Blender in float32
        np.testing.assert_allclose(seen[str(n)], x[n], rtol=0, atol=1e-6)
    np.testing.assert_allclose(seen["seq"], x[7], rtol=0, atol=1e-6)
    assert not np.allclose(seen["1"], seen["10"])  # the cache moves the mesh
