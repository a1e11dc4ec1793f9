"""Shared helpers of the echelon Python tests."""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import pytest

try:  # Python 3.11+
    import tomllib
except ModuleNotFoundError:  # Python 3.10: the same parser, as a package
    import tomli as tomllib

import echelon

REPO = Path(__file__).resolve().parents[2]


def builtin_document(name: str) -> dict:
    """A built-in scenario's TOML document as a dict."""
    return tomllib.loads(echelon.Scenario.builtin(name).source)


@pytest.fixture(scope="session")
def echelon_cli() -> Path:
    """The `echelon` binary of this workspace (built by `cargo test` before
    pytest runs in scripts/test; ECHELON_BIN names another)."""
    candidates = []
    if os.environ.get("ECHELON_BIN"):
        candidates.append(Path(os.environ["ECHELON_BIN"]))
    target = Path(os.environ.get("CARGO_TARGET_DIR", REPO / "target"))
    candidates += [target / "debug" / "echelon", target / "release" / "echelon"]
    found = shutil.which("echelon")
    if found:
        candidates.append(Path(found))
    for c in candidates:
        if c.is_file() and os.access(c, os.X_OK):
            return c
    pytest.fail("no echelon binary: run `cargo build -p echelon-cli` or set ECHELON_BIN")
