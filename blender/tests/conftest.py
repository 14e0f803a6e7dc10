"""``make test-blender``: the Blender-side checks, run with a Blender Python given as
``$BLENDER_PYTHON`` (the bpy module's venv the Makefile makes, or a ``blender`` binary);
the figures each check measured are printed at the end."""
import json
import os
import subprocess
import zipfile
from pathlib import Path

import pytest

HERE = Path(__file__).resolve().parent
ADDON = HERE.parent / "casadi_keyframe_blender"
REPORT = []


def blender_command() -> list[str]:
    given = os.environ.get("BLENDER_PYTHON")
    if not given:
        pytest.skip("set BLENDER_PYTHON to a Python with bpy or a blender binary "
                    "(make test-blender does)")
    return ([given] if Path(given).name.startswith("python")
            else [given, "-b", "--factory-startup", "--python"])


def run_blender(script: str, job: dict, tmp_path: Path, timeout: float = 900) -> dict:
    """Run ``script`` (in this folder) on ``job``; what it dumped."""
    job_file, out = tmp_path / f"{script}.job.json", tmp_path / f"{script}.out.json"
    job_file.write_text(json.dumps(job))
    run = subprocess.run([*blender_command(), str(HERE / script), "--", str(job_file), str(out)],
                         capture_output=True, text=True, timeout=timeout)
    print(run.stdout[-3000:], run.stderr[-3000:])
    assert run.returncode == 0 and out.is_file(), run.stdout[-3000:] + run.stderr[-3000:]
    return json.loads(out.read_text())


@pytest.fixture(scope="session")
def addon_zip(tmp_path_factory) -> str:
    """The add-on as a user installs it: a zip of the ``casadi_keyframe_blender`` folder."""
    path = tmp_path_factory.mktemp("addon") / "casadi_keyframe_blender.zip"
    with zipfile.ZipFile(path, "w") as z:
        for f in sorted(ADDON.glob("*")):
            if f.suffix in (".py", ".toml"):
                z.write(f, f"casadi_keyframe_blender/{f.name}")
    return str(path)


def pytest_terminal_summary(terminalreporter):
    if REPORT:
        terminalreporter.write_line("")
        for line in REPORT:
            terminalreporter.write_line(line)
