"""The notebooks of examples/ run from top to bottom and save their figures."""

from __future__ import annotations

import importlib.util
import json
import sys
from pathlib import Path

import nbformat
import pytest
from nbclient import NotebookClient

from conftest import REPO

NOTEBOOKS = sorted((REPO / "examples").glob("*.ipynb"))


def test_there_are_notebooks():
    assert NOTEBOOKS


@pytest.mark.parametrize("path", NOTEBOOKS, ids=[p.stem for p in NOTEBOOKS])
def test_notebook_runs_and_saves_its_figures(path: Path, tmp_path, monkeypatch):
    figures = tmp_path / "figures"
    # The notebook runs in this interpreter, whatever kernel named python3
    # a user installed elsewhere (`ipykernel install --user` in another
    # venv would otherwise take it there, with another echelon).
    spec = tmp_path / "jupyter" / "kernels" / "echelon-tests"
    spec.mkdir(parents=True)
    argv = [sys.executable, "-m", "ipykernel_launcher", "-f", "{connection_file}"]
    (spec / "kernel.json").write_text(json.dumps({"argv": argv, "display_name": "echelon tests", "language": "python"}))
    monkeypatch.setenv("JUPYTER_PATH", str(tmp_path / "jupyter"))
    monkeypatch.setenv("ECHELON_FIGURES", str(figures))
    monkeypatch.setenv("ECHELON_QUICK", "1")
    nb = nbformat.read(path, as_version=4)
    # A notebook that trains with a library echelon does not depend on
    # (torch: gigabytes) names it; without it here, it is skipped, named.
    missing = [m for m in nb.metadata.get("echelon", {}).get("requires", []) if importlib.util.find_spec(m) is None]
    if missing:
        pytest.skip(f"{path.name} needs {', '.join(missing)} (pip install {' '.join(missing)})")
    NotebookClient(nb, timeout=600, kernel_name="echelon-tests", resources={"metadata": {"path": str(tmp_path)}}).execute()
    saved = sorted(p.name for p in figures.glob("*.png"))
    assert saved, "the notebook saved no figure"
    for p in figures.glob("*.png"):
        assert p.read_bytes().startswith(b"\x89PNG") and p.stat().st_size > 10_000, p.name
    errors = [o for c in nb.cells if c.cell_type == "code" for o in c.get("outputs", []) if o.get("output_type") == "error"]
    assert not errors
