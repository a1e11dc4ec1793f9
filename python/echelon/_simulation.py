"""A scenario stepped under your controller's commands."""

from __future__ import annotations

import json
from typing import Any, Callable

import numpy as np

from . import _args, _echelon
from ._scenario import Scenario, _checked, as_scenario


class Simulation:
    """A scenario's robots, limits and odometry, stepped under commands from
    Python (Robotarium's loop): ``step(commands)`` applies one RK4 step with
    ``commands[i]`` held, ``(u1, u2)`` (eq. 3c–d) for a torque-driven agent
    or ``(v*, ω*)`` for a velocity base, through the agent's limits exactly
    as ``echelon run`` applies its law's command.

    A scenario with ``[safety]`` filters the commands as ``echelon run``
    filters its law's (the simulator's own filter step): ``safety=False``
    turns it off for every step, ``step(commands, filter=False)`` for one;
    :attr:`safety_step` says what the filter did at the last step.

    ``agents`` describes each agent (drive, leader, gains, robot, ...);
    ``leader(i, commands)`` gives what the paper's law needs, so a loop over
    ``order`` with :mod:`echelon.law` reproduces a sampled ``echelon run``.
    """

    def __init__(self, scenario: Scenario | str, *, safety: bool = True, **overrides: Any) -> None:
        scenario = as_scenario("scenario", scenario)
        ov = {**scenario.overrides, **_checked(overrides)}
        self.scenario = scenario
        #: Whether :meth:`step` applies the scenario's safety filter by default.
        self.safety = _args.flag("safety", safety)
        self._sim = _echelon.Simulation(scenario._inner, ov)
        self.agents: list[dict[str, Any]] = []
        for a in self._sim.agents:
            a = dict(a)
            robot_json = a.pop("robot_json")
            a["robot"] = None if robot_json is None else json.loads(robot_json)
            self.agents.append(a)

    @property
    def n(self) -> int:
        """Number of agents."""
        return self._sim.n

    @property
    def time(self) -> float:
        """Current time, s."""
        return self._sim.time

    @property
    def dt(self) -> float:
        """RK4 step, s."""
        return self._sim.dt

    @property
    def steps(self) -> int:
        """Steps of the scenario's duration."""
        return self._sim.steps

    @property
    def step_index(self) -> int:
        return self._sim.step_index

    @property
    def done(self) -> bool:
        """Whether the scenario's duration is reached."""
        return self._sim.done

    @property
    def order(self) -> list[int]:
        """Every leader before its followers (0-based indices)."""
        return self._sim.order

    @property
    def poses(self) -> np.ndarray:
        """True states, ``(n, 5)``: x, y, θ, v, ω."""
        return self._sim.poses

    @property
    def sensed(self) -> np.ndarray:
        """What each controller senses of itself, ``(n, 5)`` (its odometry
        estimate when it dead-reckons)."""
        return self._sim.sensed

    def leader(self, i: int, commands: np.ndarray | None = None) -> dict[str, Any]:
        """What agent ``i``'s law is given now: ``p``, ``dp``, ``ddp`` (the
        leader's motion) and ``lx``, ``ly``, ``dly``, ``ddly`` (eqs. 4–6). A
        robot leader accelerates under its row of ``commands``."""
        i = _args.integer("i", i)
        if commands is None:
            commands = np.zeros((self.n, 2))
        return self._sim.leader(i, _args.array("commands", commands, ndim=2, shape=f"({self.n}, 2)"))

    @property
    def has_safety(self) -> bool:
        """Whether the scenario has a safety filter (``[safety]``)."""
        return self._sim.has_safety

    def step(self, commands: np.ndarray, filter: bool | None = None) -> None:
        """One RK4 step under ``commands``, ``(n, 2)``, through the
        scenario's safety filter when it has one and ``filter`` (None: the
        simulation's :attr:`safety` switch) is true."""
        on = self.safety if filter is None else _args.flag("filter", filter)
        a = _args.array("commands", commands, ndim=2, shape=f"({self.n}, 2): (u1, u2) or (v, ω) per agent")
        self._sim.step(a, on)

    def step_by(self, law: Callable[[int, float, np.ndarray, dict[str, Any]], Any]) -> None:
        """One RK4 step of a continuous-time controller: ``law(i, t, state,
        leader)`` is called for each agent (``order``: leaders first) in each
        of RK4's four stages (and, with velocity bases, at the new state to
        settle them), where ``echelon run`` evaluates its own law, and
        returns agent ``i``'s ``(u1, u2)`` or ``(v*, ω*)``. ``state`` is what
        the agent senses at the stage (``[x, y, θ, v, ω]``), ``leader`` what
        its law is given there (as :meth:`leader`). :func:`echelon.law.own`
        is the agents' own laws as such a function. For scenarios with a
        continuous-time controller only (no ``controller_period``, no
        ``[safety]``, not stepped by :meth:`step`); an exception raised by
        ``law`` stops the step, nothing moved."""
        if not callable(law):
            raise TypeError(f"law must be callable as law(i, t, state, leader), got {_args.describe(law)}")
        self._sim.step_by(law)

    @property
    def safety_step(self) -> dict[str, Any] | None:
        """What the safety filter did at the last step, or None when it did
        not run (no ``[safety]``, switched off, no step yet). A dict of
        per-agent entries: ``ran`` (bool, the agent filters), ``active``
        (bool, its command was changed), ``outcome`` (``nominal``,
        ``filtered``, ``braked``; ``off`` for an agent without a filter),
        ``deadlock`` (bool, it is breaking a deadlock), ``nominal`` and
        ``filtered`` (``(n, 2)``: the command given, after the acceleration
        limit, and the command sent) and ``min_distance`` (m, to the nearest
        neighbour's point in range; inf: none in range)."""
        got = self._sim.safety_step()
        if got is None:
            return None
        ran, outcome, deadlock, nominal, filtered, closest = got
        outcome = list(outcome)
        return {
            "ran": np.asarray(ran, dtype=bool),
            "active": np.asarray([o in ("filtered", "braked") for o in outcome], dtype=bool),
            "outcome": outcome,
            "deadlock": np.asarray(deadlock, dtype=bool),
            "nominal": nominal,
            "filtered": filtered,
            "min_distance": np.asarray(closest, dtype=np.float64),
        }

    def errors(self) -> tuple[np.ndarray, np.ndarray]:
        """The true ``e`` (eq. 7) and ``z`` (eq. 10) now, ``(n, 2)`` each."""
        return self._sim.errors()

    def __repr__(self) -> str:
        return f"Simulation({self.scenario.name!r}, t={self.time}, n={self.n})"
