"""The control laws as functions on numpy arrays.

- :func:`paper`: the paper's backstepping law for torque-driven robots
  (eqs. 7–13; ``variant="complete"`` cancels the cross term);
- :func:`kinematic`: its first step as a velocity command, for velocity bases;
- :func:`commands`: every agent of a :class:`echelon.Simulation` under its
  own law, in Python, as ``echelon run`` evaluates it at a controller sample
  (a template for your own);
- :func:`own`: the same as a law for :meth:`echelon.Simulation.step_by`,
  evaluated in every RK4 stage (a continuous-time controller).
"""

from __future__ import annotations

import json
from typing import Any, Callable, Mapping

import numpy as np

from . import _echelon


def _vec(x: Any, n: int, name: str) -> np.ndarray:
    a = np.ascontiguousarray(x, dtype=np.float64).reshape(-1)
    if a.size != n:
        raise ValueError(f"{name}: {a.size} numbers, expected {n}")
    return a


def _offset(leader: Mapping[str, Any]) -> np.ndarray:
    return np.array(
        [leader["lx"], leader["ly"], leader.get("dly", 0.0), leader.get("ddly", 0.0)],
        dtype=np.float64,
    )


def paper(
    state: Any,
    leader: Mapping[str, Any],
    robot: Mapping[str, Any] | str,
    ke: float,
    kz: float,
    variant: str = "paper",
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The paper's law (eqs. 7–13) for a robot in ``state`` (``[x, y, θ, v,
    ω]``) behind ``leader`` (a dict with ``p``, ``dp``, ``ddp``, ``lx``,
    ``ly`` and optionally ``dly``, ``ddly``, as
    :meth:`echelon.Simulation.leader` gives it). ``robot`` holds eq. 3's
    parameters (``mass``, ``linear_friction``, ``inertia``,
    ``angular_friction``, ``half_wheelbase``, ``wheel_radius``,
    ``torque_limit``) or names a preset (``agent1``, ``agent2``: Table I).
    Returns ``u = [u1, u2]`` (before torque saturation), ``e`` (eq. 7) and
    ``z`` (eq. 10)."""
    robot_json = _echelon.robot_preset(robot) if isinstance(robot, str) else json.dumps(dict(robot))
    u, e, z = _echelon.law_paper(
        _vec(state, 5, "state"),
        _vec(leader["p"], 2, "p"),
        _vec(leader["dp"], 2, "dp"),
        _vec(leader.get("ddp", (0.0, 0.0)), 2, "ddp"),
        _offset(leader),
        robot_json,
        float(ke),
        float(kz),
        variant,
    )
    return np.array(u), np.array(e), np.array(z)


def kinematic(
    state: Any, leader: Mapping[str, Any], ke: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The kinematic law: the velocity command ``[v*, ω*]`` that makes ``e``
    decay at ``K_e`` for a robot in ``state`` (``[x, y, θ]`` or ``[x, y, θ,
    v, ω]``) behind ``leader``; returns it with ``e`` and ``z``."""
    s = np.ascontiguousarray(state, dtype=np.float64).reshape(-1)
    cmd, e, z = _echelon.law_kinematic(
        s, _vec(leader["p"], 2, "p"), _vec(leader["dp"], 2, "dp"), _offset(leader), float(ke)
    )
    return np.array(cmd), np.array(e), np.array(z)


def commands(sim: Any) -> np.ndarray:
    """Every agent's command now, ``(n, 2)``, each from its own law (the
    paper's, complete or kinematic) on what its controller senses, leaders
    first: what ``echelon run`` computes at a controller sample."""
    out = np.zeros((sim.n, 2))
    sensed = sim.sensed
    for i in sim.order:
        a = sim.agents[i]
        leader = sim.leader(i, out)
        if a["drive"] == "torque":
            out[i], _, _ = paper(sensed[i], leader, a["robot"], a["ke"], a["kz"], a["law"])
        else:
            out[i], _, _ = kinematic(sensed[i], leader, a["ke"])
    return out


def own(sim: Any) -> Callable[[int, float, np.ndarray, Mapping[str, Any]], np.ndarray]:
    """Each agent's own law (the paper's, complete or kinematic) as a
    continuous-time law for :meth:`echelon.Simulation.step_by`: ``law(i, t,
    state, leader)`` is agent ``i``'s command from what it senses and what
    its law is given at an RK4 stage."""
    agents = [dict(a) for a in sim.agents]
    for a in agents:
        # Serialised once, not in every stage.
        a["robot"] = None if a["robot"] is None else json.dumps(a["robot"])

    def law(i: int, t: float, state: np.ndarray, leader: Mapping[str, Any]) -> np.ndarray:
        a = agents[i]
        if a["drive"] == "torque":
            u, _, _ = _echelon.law_paper(
                state,
                np.asarray(leader["p"], dtype=np.float64),
                np.asarray(leader["dp"], dtype=np.float64),
                np.asarray(leader["ddp"], dtype=np.float64),
                _offset(leader),
                a["robot"],
                float(a["ke"]),
                float(a["kz"]),
                a["law"],
            )
            return np.array(u)
        cmd, _, _ = kinematic(state, leader, a["ke"])
        return cmd

    return law
