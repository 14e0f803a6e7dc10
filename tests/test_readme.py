"""The README is a landing page: at most 200 lines, every relative link and picture
resolving, and its Python example running as written."""
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
README = ROOT / "README.md"
LINK = re.compile(r"!?\[[^\]]*\]\(([^)\s]+)\)")


def relative_links(path: Path) -> list[str]:
    """The relative link targets of a Markdown file, outside code blocks, without anchors."""
    text = re.sub(r"```.*?```", "", path.read_text(), flags=re.S)
    return [t.split("#")[0] for t in LINK.findall(text)
            if not re.match(r"[a-z]+:", t) and not t.startswith("#")]


def test_the_readme_is_a_landing_page_of_at_most_200_lines():
    lines = README.read_text().splitlines()
    assert len(lines) <= 200, f"README.md has {len(lines)} lines: move text into docs/"


def test_every_relative_link_of_the_readme_resolves():
    links = relative_links(README)
    assert links, "the README links into the site's pages"
    missing = [t for t in links if not (ROOT / t).exists()]
    assert not missing, f"README.md links to files that do not exist: {missing}"


def test_the_readme_python_example_runs():
    code = re.findall(r"```python\n(.*?)```", README.read_text(), re.S)[0]
    assert "ck.solve(prob, maxiter=100)" in code
    code = code.replace("maxiter=100)", "maxiter=2, quiet=True)").replace("print(", "str(")
    scope = {}
    exec(compile(code, "README example", "exec"), scope)
    result, prob, phi = scope["result"], scope["prob"], scope["phi"]
    assert result.trajectory.x.shape == (prob.steps + 1, 30, 2)
    assert result.fun < phi and scope["grad"].shape == scope["u"].shape
