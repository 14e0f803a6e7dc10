"""The documentation site: its strict build (a renamed function, a broken link or a missing
page fails it), one gallery page with a picture per problem file, and the pages' examples
and command lines as they are written (the README's long sections moved there)."""
import importlib.util
import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

from casadi_keyframe import load_problem, solve

ROOT = Path(__file__).resolve().parent.parent
DOCS = ROOT / "docs"
TOOLS = ("mkdocs", "material", "mkdocstrings_handlers.python", "mkdocs_jupyter")


def page(name: str) -> str:
    return (DOCS / name).read_text()


def section(name: str, heading: str) -> str:
    """The text under ``heading`` (a ``## `` line) of the page, up to the next one."""
    return page(name).split(f"\n{heading}\n")[1].split("\n## ")[0]


def python_blocks(text: str) -> list[str]:
    return re.findall(r"```python\n(.*?)```", text, re.S)


def test_the_site_builds_strict(tmp_path):
    """``mkdocs build --strict``, as ``make docs`` runs it (no solve, no notebook run)."""
    absent = [t for t in TOOLS if importlib.util.find_spec(t.split(".")[0]) is None]
    if absent:
        pytest.skip(f"the docs extras are not installed ({', '.join(absent)}): "
                    "pip install -e '.[docs]' (make test installs them)")
    env = {**os.environ, "NO_MKDOCS_2_WARNING": "1"}
    run = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir",
                          str(tmp_path / "site")], cwd=ROOT, env=env, capture_output=True,
                         text=True, timeout=600)
    assert run.returncode == 0, run.stderr[-4000:]
    api = (tmp_path / "site" / "reference" / "api" / "problem.html").read_text()
    for entry in ("casadi_keyframe.ControlProblem", "casadi_keyframe.solve",
                  "casadi_keyframe.load_problem"):
        assert f'id="{entry}"' in api, entry
    models = (tmp_path / "site" / "reference" / "api" / "models.html").read_text()
    assert 'id="casadi_keyframe.models.ClothModel"' in models
    cli = (tmp_path / "site" / "reference" / "cli.html").read_text()
    assert "--time-limit SECONDS" in cli and "<!-- cli:" not in cli


def test_every_problem_file_has_a_gallery_page_with_a_picture_in_the_nav():
    from casadi_keyframe.loading import list_problems

    nav = (ROOT / "mkdocs.yml").read_text()
    for name, _ in list_problems():
        text = page(f"gallery/{name}.md")
        pictures = re.findall(r"!\[[^\]]*\]\(([^)]+)\)", text)
        assert pictures and all((DOCS / "gallery" / p).is_file() for p in pictures), name
        assert f"gallery/{name}.md" in nav, f"mkdocs.yml's nav has no gallery page for {name}"
        assert "## Measured" in text and f"casadi-keyframe solve {name}" in text, name


def test_the_layout_page_names_every_module():
    layout = page("layout.md")
    package = ROOT / "casadi_keyframe"
    modules = [p.name for p in package.glob("*.py") if not p.name.startswith("_")]
    modules += [p.name + "/" for p in package.iterdir() if (p / "__init__.py").exists()]
    missing = [m for m in modules if f"`{m}`" not in layout]
    assert not missing, f"docs/layout.md omits {missing}: one phrase each, please"


def test_the_problem_file_example_runs_and_reaches_its_keyframes(tmp_path):
    code = python_blocks(page("guides/problem-files.md"))[0]
    path = tmp_path / "gather.py"
    path.write_text(code)
    result = solve(load_problem(path, agents=12), maxiter=100, quiet=True)
    region, com = result.breakdown["misses"]
    assert region["fraction_inside"] >= 0.95 and com["position_error"] < 0.05


def test_the_cloth_example_runs():
    code = next(c for c in python_blocks(page("guides/models.md")) if "ClothModel" in c)
    code = code.replace("maxiter=20,", "maxiter=5, quiet=True,").replace("maxiter=20)", "maxiter=5, quiet=True)")
    scope = {}
    exec(compile(code, "the cloth example", "exec"), scope)
    result, prob = scope["result"], scope["prob"]
    assert result.fun < prob.objective(prob.initial_controls())
    assert abs(result.trajectory.x[-1, 0] - prob.x0[0]).max() == 0  # the pin held


def test_the_export_commands_run(tmp_path, monkeypatch):
    """Each `casadi-keyframe export` line of the page runs on a (small) cloth_toss result
    and writes the files its comment names."""
    from casadi_keyframe import cli

    monkeypatch.chdir(tmp_path)
    assert cli.main(["solve", "cloth_toss", "--set", "rows=3", "--set", "cols=3", "--set",
                     "steps=6", "--maxiter", "1", "--quiet", "--no-animation", "--no-viewer",
                     "--out", "results/cloth_toss"]) in (0, 3)
    block = re.findall(r"```sh\n(.*?)```", section("guides/meshes-and-blender.md",
                                                   "## Export formats"), re.S)[0]
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


def test_the_blender_clicks_are_the_tested_ones():
    """The settings the Blender steps name are those tests/blender_mesh_cache.py (run by
    tests/test_blender.py in Blender) uses, and the frame rate and range are cloth_toss's."""
    clicks = " ".join(section("guides/meshes-and-blender.md",
                              "## Use the result in Blender").split())
    script = (Path(__file__).parent / "blender_mesh_cache.py").read_text()
    assert "Forward Axis: Y and Up Axis: Z" in clicks
    assert "forward_axis='Y', up_axis='Z'" in script
    assert "File Format: PC2" in clicks and "cache_format = 'PC2'" in script
    assert "Frame Start: 1" in clicks and "mod.frame_start = 1" in script
    prob = load_problem("cloth_toss", rows=2, cols=2)
    assert f"FPS {round(1 / prob.dt)} (1 / dt)" in clicks
    assert f"End = steps + 1 ({prob.steps + 1})" in clicks
