"""Execute the notebooks and store them with their outputs, so they read on any code host.

    python notebooks/execute.py [NAME.ipynb ...]

Needs the ``test`` extra (nbclient, nbformat, ipykernel). The tests execute the notebooks again
from a copy without outputs and check their printed answers (tests/test_notebooks.py).
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import nbclient
import nbformat

HERE = Path(__file__).resolve().parent


def execute(path: Path) -> float:
    """Execute ``path`` in place (outputs replaced); return the wall time [s]."""
    nb = nbformat.read(path, as_version=4)
    for cell in nb.cells:
        if cell.cell_type == "code":
            cell.outputs, cell.execution_count = [], None
    t0 = time.perf_counter()
    nbclient.NotebookClient(
        nb, timeout=1200, kernel_name="python3", resources={"metadata": {"path": str(HERE)}}
    ).execute()
    nbformat.write(nb, path)
    return time.perf_counter() - t0


def main(names: list[str]) -> None:
    for path in [HERE / n for n in names] or sorted(HERE.glob("*.ipynb")):
        seconds = execute(path)
        print(f"{path.name}: executed in {seconds:.1f} s, {path.stat().st_size / 1024:.0f} KiB")


if __name__ == "__main__":
    main(sys.argv[1:])
