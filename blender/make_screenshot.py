"""docs/blender_mesh_keyframes.png: the README's 30 x 30 walkthrough solved by the add-on in
Blender and rendered headless at both keyframes (``bl_screenshot.py``), the two renders side
by side with each keyframe's frame and miss written under it.

    BLENDER_PYTHON=.venv-blender/bin/python .venv/bin/python blender/make_screenshot.py
"""
import json
import os
import subprocess
import sys
import tempfile
import zipfile
from pathlib import Path

from PIL import Image, ImageDraw, ImageFont

from casadi_keyframe.scenes.mesh_targets import write_sheet_and_targets

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent


def addon_zip(work: Path) -> Path:
    """The add-on as a user installs it, zipped into ``work``."""
    path = work / "casadi_keyframe_blender.zip"
    with zipfile.ZipFile(path, "w") as z:
        for f in sorted((HERE / "casadi_keyframe_blender").glob("*")):
            if f.suffix in (".py", ".toml"):
                z.write(f, f"casadi_keyframe_blender/{f.name}")
    return path


def main() -> None:
    work = Path(tempfile.mkdtemp(prefix="ckf_shot_"))
    files = write_sheet_and_targets(work / "meshes", 30, 30)
    addon = addon_zip(work)
    job = {"addon": str(addon), "out": str(work),
           "executable": str(Path(sys.executable).with_name("casadi-keyframe")),
           "sheet": str(files["sheet"]), "pins": [0, 29],
           "targets": {"wave": [str(files["wave"]), 41], "fold": [str(files["fold"]), 81]},
           "renders": [["wave", 21], ["wave", 41], ["fold", 81]],
           "camera": [2.0, -1.7, 0.45], "aim": [0.5, 0.2, -0.45]}
    (work / "job.json").write_text(json.dumps(job))
    subprocess.run([os.environ.get("BLENDER_PYTHON", ".venv-blender/bin/python"),
                    str(HERE / "bl_screenshot.py"), "--", str(work / "job.json")], check=True)
    seen = json.loads((work / "seen.json").read_text())
    shots = [Image.open(work / f"frame_{frame}.png").convert("RGB")
             for _, frame in job["renders"]]
    width, height = shots[0].size
    sheet = Image.new("RGB", (width * len(shots), height + 70), "white")
    draw = ImageDraw.Draw(sheet)
    try:
        font = ImageFont.truetype("DejaVuSans.ttf", 20)
    except OSError:
        font = ImageFont.load_default()
    keyframes = {name: frame for name, (_, frame) in job["targets"].items()}
    for k, ((name, frame), shot) in enumerate(zip(job["renders"], shots)):
        rms = seen["rms"][f"{name}@{frame}"]
        what = ("keyframe" if keyframes[name] == frame
                else f"on the way (keyframe {keyframes[name]})")
        sheet.paste(shot, (k * width, 0))
        draw.text((k * width + 16, height + 8), f"frame {frame}, {what}: {name} shape key in "
                  f"red", fill="black", font=font)
        draw.text((k * width + 16, height + 38), f"cloth (blue) {1e3 * rms:.2g} mm rms off "
                  f"it: {'hit' if rms <= 0.01 else 'not there yet'}", fill="black", font=font)
    target = ROOT / "docs" / "blender_mesh_keyframes.png"
    sheet.save(target)
    print(f"{target}; the add-on reported: {seen['misses']}")


if __name__ == "__main__":
    main()
