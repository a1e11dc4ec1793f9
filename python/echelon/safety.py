"""The barrier-certificate safety filter (docs/safety.md) on numpy arrays,
for velocity-controlled robots, used as Robotarium's barrier certificates
are: compute nominal ``(v, ω)`` commands, filter them, send them.

Each robot's point ``l`` ahead of its centre is kept ``radius`` from the
other robots' points and from obstacles' edges: the commands are the
nearest (least squares on ``(v, l ω)``) that keep ``ḣ ≥ −γ h`` for every
pair, each robot taking half of each shared constraint.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from . import _echelon


class Filter:
    """Filters for ``n`` robots, kept between calls (each robot's deadlock
    monitor remembers), at control period ``period`` s. ``obstacles`` are
    rows of ``(x, y, r)``; ``base`` names a velocity base preset whose
    limits bound the commands (``ideal``: none)."""

    def __init__(
        self,
        n: int,
        radius: float,
        *,
        gain: float = 1.0,
        range: float = float("inf"),
        l: float = 0.1,
        obstacles: Any = None,
        period: float = 0.01,
        base: str = "ideal",
    ) -> None:
        obs = None if obstacles is None else np.ascontiguousarray(obstacles, dtype=np.float64).reshape(-1, 3)
        self._inner = _echelon.SafetyFilters(n, radius, gain, range, l, obs, period, base)
        self.n = n
        self.l = l
        self.radius = radius
        self.outcomes: list[str] = []
        self.min_distance: list[float] = []

    def __call__(self, poses: Any, commands: Any, t: float = 0.0) -> np.ndarray:
        """The filtered commands ``(n, 2)`` for robots at ``poses`` (``(n,
        3)``: x, y, θ, moving at their commands; or ``(n, 5)`` with their v,
        ω) asking for ``commands`` ``(n, 2)`` at time ``t``. ``outcomes``
        and ``min_distance`` then hold what each robot's filter did."""
        out, self.outcomes, self.min_distance = self._inner.filter(
            float(t),
            np.ascontiguousarray(poses, dtype=np.float64),
            np.ascontiguousarray(commands, dtype=np.float64),
        )
        return out


def filter(
    poses: Any,
    commands: Any,
    *,
    radius: float,
    obstacles: Any = None,
    gain: float = 1.0,
    range: float = float("inf"),
    l: float = 0.1,
    period: float = 0.01,
    base: str = "ideal",
) -> np.ndarray:
    """One filtering of ``commands`` (``(n, 2)``: v, ω) for robots at
    ``poses`` (see :class:`Filter`, which keeps the filters between calls)."""
    p = np.ascontiguousarray(poses, dtype=np.float64)
    f = Filter(p.shape[0], radius, gain=gain, range=range, l=l, obstacles=obstacles, period=period, base=base)
    return f(p, commands)


def points(poses: Any, l: float = 0.1) -> np.ndarray:
    """The points the filter keeps apart: ``l`` ahead of each robot, ``(n, 2)``."""
    p = np.asarray(poses, dtype=np.float64)
    return np.stack([p[:, 0] + l * np.cos(p[:, 2]), p[:, 1] + l * np.sin(p[:, 2])], axis=1)
