"""The notebooks in notebooks/ run from top to bottom and their final checks pass.

Each notebook is executed with nbclient in a fresh ``python3`` kernel (the test process's
environment, so the kernel imports the same ``pprender`` as the tests; ``MPLBACKEND=Agg``
so that no figure is shown), with a 300 s limit per cell; any cell error fails the test.
Every notebook ends with a cell of ``assert`` statements on its key claims that prints
``ALL CHECKS PASSED: <name>``; the test requires that line from the last code cell, and
the ``pprender ... from <path>`` line of the first code cell to name the package the
tests import. Notebooks are committed without outputs, which is checked too.
"""

from __future__ import annotations

import os
import time
from pathlib import Path

import nbformat
import pytest
from nbclient import NotebookClient

import pprender

ROOT = Path(__file__).resolve().parents[1]
NOTEBOOKS = sorted((ROOT / "notebooks").glob("*.ipynb"))
EXPECTED = [
    "01_quickstart",
    "02_signatures",
    "03_classification",
    "04_fitting",
    "05_speed_vs_accuracy",
    "06_receiver_statistics",
]


def _stdout(cell: nbformat.NotebookNode) -> str:
    return "".join(o.get("text", "") for o in cell.get("outputs", []) if o.get("output_type") == "stream")


def test_the_notebooks_are_there() -> None:
    assert [p.stem for p in NOTEBOOKS] == EXPECTED


@pytest.mark.parametrize("path", NOTEBOOKS, ids=[p.stem for p in NOTEBOOKS])
def test_notebook_runs_and_its_checks_pass(path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    nb = nbformat.read(path, as_version=4)
    code = [c for c in nb.cells if c.cell_type == "code"]
    # committed clean: no outputs, no execution counts
    assert all(not c.get("outputs") and c.get("execution_count") is None for c in code), path.name
    # the kernel inherits this environment: the package the tests import, no GUI backend
    pkg_parent = str(Path(pprender.__file__).resolve().parents[1])
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join([pkg_parent] + [p for p in [os.environ.get("PYTHONPATH")] if p]))
    monkeypatch.setenv("MPLBACKEND", "Agg")
    client = NotebookClient(nb, timeout=300, kernel_name="python3", resources={"metadata": {"path": str(path.parent)}})
    t0 = time.perf_counter()
    client.execute()
    print(f"{path.name}: {time.perf_counter() - t0:.1f} s")
    first, last = _stdout(code[0]), _stdout(code[-1])
    assert f"from {Path(pprender.__file__).resolve()}" in first, first
    assert f"ALL CHECKS PASSED: {path.stem}" in last, last
