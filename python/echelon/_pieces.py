"""Theorem 2 and identification."""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

from . import _args, _echelon


def bound(
    ke: float,
    zeta: float,
    *,
    kz: float | None = None,
    omega_max: float | None = None,
    gamma: float = 0.99,
    steps: int | None = None,
    max_z: float | None = None,
    max_e: float | None = None,
    ts: float | None = None,
    law: str = "paper",
) -> dict[str, Any]:
    """Theorem 2 (``echelon bound``), both ways.

    Forward, with ``steps`` (``N``, odometry samples between fixes): the
    ultimate bound on ‖z‖. Inverse, with ``max_z`` (paper's law) or
    ``max_e`` (kinematic law): the largest ``N`` that keeps it. ``law`` is
    ``"paper"`` (``echelon bound``'s ``dynamic``; ``"complete"`` is the same
    bound) or ``"kinematic"``. The paper's law needs ``kz`` and ``omega_max``: ``z_bound = √2 K_e N ζ √(K_z² +
    ω_M²) / (K_z γ)``; the kinematic law's form is ``z_bound = √2 K_e N ζ``,
    ``e_bound = √2 N ζ / γ``. ``ts`` (the sample period, s) adds
    ``fix_period_s = N T_s``. Returns a dict of ``z_bound``, ``e_bound``,
    ``steps`` and ``fix_period_s``."""
    return _echelon.bound(
        _args.number("ke", ke),
        _args.number("zeta", zeta),
        _args.optional_number("kz", kz),
        _args.optional_number("omega_max", omega_max),
        _args.number("gamma", gamma),
        _args.optional_integer("steps", steps),
        _args.optional_number("max_z", max_z),
        _args.optional_number("max_e", max_e),
        _args.optional_number("ts", ts),
        _args.text("law", law),
    )


def identify(
    log: Any, agent: int = 1, model: str | None = None, name: str = "identified"
) -> dict[str, Any]:
    """Identifies a robot (``echelon identify``): eq. 3's ``m, η, J, ψ``
    (``model="torque"``) or a velocity base's lags and limits
    (``"velocity"``; by default from the log's columns) from ``log``: a run
    directory or ``trajectory.csv`` path, an :class:`echelon.Run`, or a
    pandas DataFrame with ``trajectory.csv``'s columns. Returns the result
    (parameters with 95 % intervals, fit checks) as a dict, with its
    ``[robots.NAME]`` block under ``"robot_toml"``."""
    from ._scenario import Run

    agent = _args.integer("agent", agent, low=1)
    model = None if model is None else _args.text("model", model)
    name = _args.text("name", name)
    if isinstance(log, Run):
        log = log.dir
    if isinstance(log, (str, os.PathLike)):
        text, toml = _echelon.identify_log(path=Path(log), agent=agent, model=model, name=name)
    elif hasattr(log, "to_csv"):
        csv = log.to_csv(index=False, float_format="%.17g")
        text, toml = _echelon.identify_log(csv=csv, agent=agent, model=model, name=name)
    else:
        raise TypeError(f"log must be a path, an echelon.Run or a pandas DataFrame, got {_args.describe(log)}")
    out = json.loads(text)
    out["robot_toml"] = toml
    return out
