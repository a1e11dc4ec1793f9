"""The barrier-certificate safety filter (docs/safety.md) on numpy arrays,
used as Robotarium's barrier certificates are: compute nominal commands,
filter them, send them.

Each robot's point ``l`` ahead of its centre is kept ``radius`` from the
other robots' points and from obstacles' edges, each robot taking half of
each shared constraint:

- velocity bases (:class:`Filter`, :func:`filter`): the ``(v, ω)`` nearest
  (least squares on ``(v, l ω)``) that keeps ``ḣ ≥ −γ h`` for every pair;
- torque-driven robots (eq. 3; :class:`TorqueFilter`, :func:`torque_filter`):
  the ``(u1, u2)`` nearest (least squares on the point's acceleration
  ``(u1/m, l u2/J)``) that keeps ``ḧ + (γ + p) ḣ + γ p h ≥ 0`` (``p`` =
  ``max(γ, INNER_RATE)``), within the speed envelope (:data:`ENVELOPE`) and
  the robot's wheel torque limit.
"""

from __future__ import annotations

from typing import Any, Mapping, Sequence

import numpy as np

from . import _args, _echelon

#: ``p``, 1/s: the inner pole of the torque barrier (``ψ̇₁ + p ψ₁ ≥ 0``,
#: ``ψ₁ = ḣ + γ h``, ``p = max(γ, INNER_RATE)``).
INNER_RATE: float = _echelon.TORQUE_INNER_RATE

#: The speed envelope a torque robot's filtered command keeps it in:
#: ``v_max`` (m/s), ``v_reverse`` (m/s, ``v ≥ −v_reverse``), ``omega_max``
#: (rad/s) and ``rate`` (``κ``, 1/s: how fast the state is brought back).
ENVELOPE: dict[str, float] = dict(
    zip(("v_max", "v_reverse", "omega_max", "rate"), _echelon.TORQUE_ENVELOPE)
)


class Filter:
    """Filters for ``n`` robots, kept between calls (each robot's deadlock
    monitor remembers), at control period ``period`` s. ``obstacles`` are
    rows of ``(x, y, r)``. ``base`` is the velocity base whose lags and
    limits bound the commands: a preset's name (``ideal``: none;
    ``turtlebot3-burger``, ``turtlebot4``, ``jackal``) or a mapping spelled
    as a scenario's ``[robots.NAME]`` velocity base: ``preset`` (default
    ``ideal``) overridden by any of ``tau_v``, ``tau_omega`` (lags, s),
    ``v_max`` (m/s), ``omega_max`` (rad/s), ``a_max`` (m/s²),
    ``alpha_max`` (rad/s²) (``float("inf")``: no limit), ``accel``
    (``"joint"`` or ``"per-axis"``); ``drive`` may say ``"velocity"``.
    An unknown key (``reverse_limit`` too: the filter keeps no backup
    budget), a value of the wrong type (``TypeError``) or out of its domain
    (``ValueError``: a limit ≤ 0 or NaN, a negative lag, ``a_max`` without
    ``tau_v``) is refused naming it (``base.v_max``)."""

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
        base: str | Mapping[str, Any] = "ideal",
    ) -> None:
        self._inner = _echelon.SafetyFilters(
            _args.integer("n", n),
            _args.number("radius", radius),
            _args.number("gain", gain),
            _args.number("range", range),
            _args.number("l", l),
            _obstacles(obstacles),
            _args.number("period", period),
            _base(base),
        )
        self.n = n
        self.l = l
        self.radius = radius
        self.outcomes: list[str] = []
        self.min_distance: list[float] = []

    def __call__(self, poses: Any, commands: Any, t: float = 0.0) -> np.ndarray:
        """The filtered commands ``(n, 2)`` for robots at ``poses`` (``(n,
        3)``: x, y, θ, moving at the commands this filter returned for them
        at the last call, which the caller sent them (at the first call, at
        ``commands``); or ``(n, 5)`` with their v, ω) asking for
        ``commands`` ``(n, 2)`` at time ``t``. ``outcomes`` and
        ``min_distance`` then hold what each robot's filter did."""
        out, self.outcomes, self.min_distance = self._inner.filter(
            _args.number("t", t, finite=True),
            _args.array("poses", poses),
            _args.array("commands", commands),
        )
        return out


def _base(base: Any) -> str | dict[str, Any]:
    """A velocity base for the extension: a preset's name, or a mapping's
    items as a dict (the extension checks its keys and values)."""
    if isinstance(base, str):
        return base
    if isinstance(base, Mapping):
        return dict(base)
    raise TypeError(
        f"base must be a velocity base preset's name or a mapping of its lags and limits, got {_args.describe(base)}"
    )


def _obstacles(obstacles: Any) -> np.ndarray | None:
    """Rows of ``(x, y, r)`` (a flat list of them too), or None."""
    if obstacles is None:
        return None
    a = _args.array("obstacles", obstacles)
    return a.reshape(-1, 3) if a.ndim == 1 and a.size % 3 == 0 else a


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
    base: str | Mapping[str, Any] = "ideal",
) -> np.ndarray:
    """One filtering of ``commands`` (``(n, 2)``: v, ω) for robots at
    ``poses`` (see :class:`Filter`, which keeps the filters between calls)."""
    p = _args.array("poses", poses, ndim=2, shape="(n, 3) or (n, 5)")
    f = Filter(p.shape[0], radius, gain=gain, range=range, l=l, obstacles=obstacles, period=period, base=base)
    return f(p, commands)


class TorqueFilter:
    """Filters for ``n`` torque-driven robots (eq. 3), kept between calls
    (each robot's deadlock monitor remembers). ``robot`` holds eq. 3's
    parameters (``mass``, ``linear_friction``, ``inertia``,
    ``angular_friction``, ``half_wheelbase``, ``wheel_radius``,
    ``torque_limit``: a dict, as ``Simulation.agents[i]["robot"]``) or
    names a preset (``agent1``, ``agent2``: Table I), for every robot, or
    is a list of them, one per robot. ``gain`` is ``γ`` (1/s), ``range``
    the sensing range (m), ``obstacles`` rows of ``(x, y, r)``."""

    def __init__(
        self,
        n: int,
        radius: float,
        *,
        robot: Mapping[str, Any] | str | Sequence[Mapping[str, Any] | str] = "agent1",
        gain: float = 1.0,
        range: float = float("inf"),
        l: float = 0.1,
        obstacles: Any = None,
    ) -> None:
        if isinstance(robot, (str, Mapping)):
            robots = [_args.robot_json("robot", robot)]
        elif isinstance(robot, Sequence):
            robots = [_args.robot_json(f"robot[{i}]", r) for i, r in enumerate(robot)]
        else:
            robots = [_args.robot_json("robot", robot)]  # refused, naming robot
        self._inner = _echelon.TorqueSafetyFilters(
            _args.integer("n", n),
            _args.number("radius", radius),
            robots,
            _args.number("gain", gain),
            _args.number("range", range),
            _args.number("l", l),
            _obstacles(obstacles),
        )
        self.n = n
        self.l = l
        self.radius = radius
        self.outcomes: list[str] = []
        self.min_distance: list[float] = []

    def __call__(self, states: Any, commands: Any, t: float = 0.0) -> np.ndarray:
        """The filtered inputs ``(n, 2)`` (``u1``, ``u2``) for robots in
        ``states`` (``(n, 5)``: x, y, θ, v, ω) asking for ``commands``
        ``(n, 2)`` at time ``t``. ``outcomes`` and ``min_distance`` then hold
        what each robot's filter did."""
        out, self.outcomes, self.min_distance = self._inner.filter(
            _args.number("t", t, finite=True),
            _args.array("states", states),
            _args.array("commands", commands),
        )
        return out


def torque_filter(
    states: Any,
    commands: Any,
    *,
    radius: float,
    robot: Mapping[str, Any] | str | Sequence[Mapping[str, Any] | str] = "agent1",
    obstacles: Any = None,
    gain: float = 1.0,
    range: float = float("inf"),
    l: float = 0.1,
) -> np.ndarray:
    """One filtering of torque robots' ``commands`` (``(n, 2)``: u1, u2) in
    ``states`` (``(n, 5)``; see :class:`TorqueFilter`, which keeps the
    filters between calls)."""
    s = _args.array("states", states, ndim=2, shape="(n, 5)")
    f = TorqueFilter(s.shape[0], radius, robot=robot, gain=gain, range=range, l=l, obstacles=obstacles)
    return f(s, commands)


def points(poses: Any, l: float = 0.1) -> np.ndarray:
    """The points the filter keeps apart: ``l`` ahead of each robot, ``(n, 2)``
    (``poses``: ``(n, 3)`` or ``(n, 5)``, x, y, θ first)."""
    p = _args.array("poses", poses, ndim=2, shape="(n, 3) or (n, 5)")
    if p.shape[1] not in (3, 5):
        raise ValueError(f"poses must be an array of numbers of shape (n, 3) or (n, 5), got one of shape {p.shape}")
    if not np.all(np.isfinite(p)):
        raise ValueError("poses: not all finite")
    l = _args.number("l", l, finite=True)
    return np.stack([p[:, 0] + l * np.cos(p[:, 2]), p[:, 1] + l * np.sin(p[:, 2])], axis=1)
