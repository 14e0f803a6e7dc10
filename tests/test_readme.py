"""The README's example problem file runs and reaches its keyframes."""
import re
from pathlib import Path

from casadi_keyframe import load_problem, solve


def test_readme_problem_file(tmp_path):
    text = (Path(__file__).parent.parent / "README.md").read_text()
    code = re.findall(r"```python\n(.*?)```", text, re.S)[0]
    path = tmp_path / "gather.py"
    path.write_text(code)
    result = solve(load_problem(path, agents=12), maxiter=100, quiet=True)
    region, com = result.breakdown["misses"]
    assert region["fraction_inside"] >= 0.95 and com["position_error"] < 0.05


def test_readme_cloth_example_runs():
    text = (Path(__file__).parent.parent / "README.md").read_text()
    code = next(c for c in re.findall(r"```python\n(.*?)```", text, re.S) if "ClothModel" in c)
    code = code.replace("maxiter=20)", "maxiter=5, quiet=True)")
    scope = {}
    exec(compile(code, "README cloth example", "exec"), scope)
    result, prob = scope["result"], scope["prob"]
    assert result.fun < prob.objective(prob.initial_controls())
    assert abs(result.trajectory.x[-1, 0] - prob.x0[0]).max() == 0  # the pin held


def test_the_readme_layout_names_every_module():
    layout = (Path(__file__).parent.parent / "README.md").read_text().split("## Layout")[1]
    package = Path(__file__).parent.parent / "casadi_keyframe"
    modules = [p.name for p in package.glob("*.py") if not p.name.startswith("_")]
    modules += [p.name + "/" for p in package.iterdir() if (p / "__init__.py").exists()]
    missing = [m for m in modules if f"`{m}`" not in layout]
    assert not missing, f"README's Layout section omits {missing}: one phrase each, please"


def _export_section() -> str:
    text = (Path(__file__).parent.parent / "README.md").read_text()
    return text.split("## Export, the viewer and Blender")[1].split("\n## ")[0]


def test_readme_export_commands_run(tmp_path, monkeypatch):
    """Each `casadi-keyframe export` line of the README runs on a (small) cloth_toss result
    and writes the files its comment names."""
    import shlex

    from casadi_keyframe import cli

    monkeypatch.chdir(tmp_path)
    assert cli.main(["solve", "cloth_toss", "--set", "rows=3", "--set", "cols=3", "--set",
                     "steps=6", "--maxiter", "1", "--quiet", "--no-animation", "--no-viewer",
                     "--out", "results/cloth_toss"]) in (0, 3)
    block = re.findall(r"```sh\n(.*?)```", _export_section(), re.S)[0]
    lines = [line.split("#")[0].split() for line in block.splitlines()]
    exports = [words for words in lines if words[1:2] == ["export"]]
    assert {words[-1] for words in exports} == {"pc2", "obj", "usd", "html"}
    for words in exports:
        if words[-1] == "usd":
            try:
                import pxr  # noqa: F401
            except ImportError:
                continue
        assert cli.main(shlex.split(" ".join(words[1:]))) == 0, words
    folder = tmp_path / "results/cloth_toss"
    for name in ("cloth_toss.pc2", "cloth_toss_rest.obj", "obj/cloth_toss_0000.obj",
                 "viewer.html"):
        assert (folder / name).is_file(), name


def test_readme_blender_clicks_are_the_tested_ones():
    """The settings the Blender steps name are those tests/blender_mesh_cache.py (run by
    tests/test_blender.py in Blender) uses, and the frame rate and range are cloth_toss's."""
    from casadi_keyframe import load_problem

    clicks = " ".join(_export_section().split("### Use the result in Blender")[1].split())
    script = (Path(__file__).parent / "blender_mesh_cache.py").read_text()
    assert "Forward Axis: Y and Up Axis: Z" in clicks
    assert "forward_axis='Y', up_axis='Z'" in script
    assert "File Format: PC2" in clicks and "cache_format = 'PC2'" in script
    assert "Frame Start: 1" in clicks and "mod.frame_start = 1" in script
    prob = load_problem("cloth_toss", rows=2, cols=2)
    assert f"FPS {round(1 / prob.dt)} (1 / dt)" in clicks
    assert f"End = steps + 1 ({prob.steps + 1})" in clicks
