"""Run the study notebooks in place and store their outputs (the committed versions).

    .venv/bin/python notebooks/execute.py [NAME.ipynb ...]     # full run
    CASADI_KEYFRAME_QUICK=1 .venv/bin/python notebooks/execute.py --check   # quick, not saved
"""
import sys
import time
from pathlib import Path

import nbformat
from nbclient import NotebookClient

HERE = Path(__file__).parent


def execute(path: Path, save: bool = True, timeout: int = 3600) -> float:
    """Execute one notebook in its folder; returns seconds."""
    nb = nbformat.read(path, as_version=4)
    start = time.perf_counter()
    NotebookClient(nb, timeout=timeout, kernel_name="python3",
                   resources={"metadata": {"path": str(path.parent)}}).execute()
    if save:
        nbformat.write(nb, path)
    return time.perf_counter() - start


if __name__ == "__main__":
    names = [a for a in sys.argv[1:] if not a.startswith("--")]
    paths = [HERE / n for n in names] or sorted(HERE.glob("*.ipynb"))
    for p in paths:
        print(f"{p.name}: {execute(p, save='--check' not in sys.argv):.0f} s", flush=True)
