"""docs/gallery/rigged_cape.png: the rigged example (``rigged_cape.py``) solved by the
add-on in Blender and rendered headless (``bl_rig_screenshot.py``) at frames on the way and
at its keyframe, side by side with each frame's caption, and ``docs/gallery/rigged_cape.json``
with what was measured (the add-on's misses, the solve's seconds, the commit).

    BLENDER_PYTHON=.venv-blender/bin/python .venv/bin/python blender/make_rig_screenshot.py
"""
import json
import math
import os
import subprocess
import sys
import tempfile
from pathlib import Path

from PIL import Image, ImageDraw, ImageFont

from make_screenshot import addon_zip

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
RENDERS = [1, 12, 24]  # scene frames: the start, on the way, the keyframe


def caption(frame: int, seen: dict) -> list[str]:
    """What the render at ``frame`` shows, and how far the character has walked and
    turned by then: two lines."""
    what = ("the keyframe (its target in red)" if frame == seen["key_frame"] else
            "the start, at rest" if frame == RENDERS[0] else "on the way")
    walked, turned = seen["walked"][str(frame)], math.degrees(seen["turned"][str(frame)])
    return [f"frame {frame}: {what}", f"walked {walked:.2f} m, turned {turned:.0f} degrees"]


def main() -> None:
    sys.path.insert(0, str(ROOT / "docs"))
    from gallery import commit_of

    work = Path(tempfile.mkdtemp(prefix="ckf_rig_"))
    job = {"addon": str(addon_zip(work)), "out": str(work), "build": {}, "maxiter": 40,
           "executable": str(Path(sys.executable).with_name("casadi-keyframe")),
           "renders": RENDERS, "camera": [2.3, -0.9, 0.3]}
    (work / "job.json").write_text(json.dumps(job))
    subprocess.run([os.environ.get("BLENDER_PYTHON", ".venv-blender/bin/python"),
                    str(HERE / "bl_rig_screenshot.py"), "--", str(work / "job.json")],
                   check=True)
    seen = json.loads((work / "seen.json").read_text())
    shots = [Image.open(work / f"rig_{frame}.png").convert("RGB") for frame in RENDERS]
    width, height = shots[0].size
    sheet = Image.new("RGB", (width * len(shots), height + 64), "white")
    draw = ImageDraw.Draw(sheet)
    try:
        font = ImageFont.truetype("DejaVuSans.ttf", 18)
    except OSError:
        font = ImageFont.load_default()
    for k, (frame, shot) in enumerate(zip(RENDERS, shots)):
        sheet.paste(shot, (k * width, 0))
        for row, text in enumerate(caption(frame, seen)):
            draw.text((k * width + 16, height + 8 + 26 * row), text, fill="black", font=font)
    target = ROOT / "docs" / "gallery" / "rigged_cape.png"
    sheet.save(target)
    record = {**seen, "commit": commit_of(), "command": "blender/make_rig_screenshot.py"}
    target.with_suffix(".json").write_text(json.dumps(record, indent=2) + "\n")
    print(f"{target}; the add-on reported: {seen['misses']} in {seen['seconds']:.0f} s")


if __name__ == "__main__":
    main()
