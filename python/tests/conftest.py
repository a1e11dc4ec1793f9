"""Shared helpers of the echelon Python tests."""

from __future__ import annotations

import os
import shutil
import threading
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


def worst_position_gap(run, poses) -> float:
    """The largest |x| or |y| difference between a run's trajectory (logged
    every step) and `poses[t][agent - 1]` stepped from Python; every logged
    row must have its pose."""
    t = run.trajectory
    assert len(t) == len(poses) * len(run.agents)
    worst = 0.0
    for (time, k), row in t.groupby(["t", "agent"]):
        p = poses[round(time, 9)][k - 1]
        worst = max(worst, abs(p[0] - row["x"].iloc[0]), abs(p[1] - row["y"].iloc[0]))
    return worst


def counts_while(call) -> int:
    """How often a Python thread spinning on the GIL counts while `call()`
    runs: an extension call that holds the GIL lets it count nearly nothing."""
    ticks = 0
    stop = threading.Event()
    started = threading.Event()

    def spin():
        nonlocal ticks
        started.set()
        while not stop.is_set():
            ticks += 1

    t = threading.Thread(target=spin)
    t.start()
    started.wait()
    before = ticks
    call()
    during = ticks - before
    stop.set()
    t.join()
    return during


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
