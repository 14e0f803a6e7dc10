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
