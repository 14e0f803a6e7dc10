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
