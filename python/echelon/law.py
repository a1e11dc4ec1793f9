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

from . import _args, _echelon


def _vec(x: Any, n: int, name: str) -> np.ndarray:
    a = _args.array(name, x).reshape(-1)
    if a.size != n:
        raise ValueError(f"{name}: {a.size} numbers, expected {n}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name}: {a.tolist()} is not finite")
    return a


def _leader(leader: Any, keys: tuple[str, ...]) -> Mapping[str, Any]:
    """``leader``, a mapping holding ``keys`` (as :meth:`echelon.Simulation.leader` gives it)."""
    if not isinstance(leader, Mapping):
        raise TypeError(
            f"leader must be a dict of p, dp, ddp, lx, ly (as Simulation.leader gives it), got {_args.describe(leader)}"
        )
    missing = [k for k in keys if k not in leader]
    if missing:
        raise ValueError(f"leader: missing {', '.join(missing)}")
    return leader


def _offset(leader: Mapping[str, Any]) -> np.ndarray:
    return np.array(
        [
            _args.number(f"leader['{k}']", leader.get(k, 0.0), finite=True)
            for k in ("lx", "ly", "dly", "ddly")
        ],
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
    leader = _leader(leader, ("p", "dp", "lx", "ly"))
    u, e, z = _echelon.law_paper(
        _vec(state, 5, "state"),
        _vec(leader["p"], 2, "leader['p']"),
        _vec(leader["dp"], 2, "leader['dp']"),
        _vec(leader.get("ddp", (0.0, 0.0)), 2, "leader['ddp']"),
        _offset(leader),
        _args.robot_json("robot", robot),
        _args.number("ke", ke),
        _args.number("kz", kz),
        _args.text("variant", variant),
    )
    return np.array(u), np.array(e), np.array(z)


def kinematic(
    state: Any, leader: Mapping[str, Any], ke: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The kinematic law: the velocity command ``[v*, ω*]`` that makes ``e``
    decay at ``K_e`` for a robot in ``state`` (``[x, y, θ]`` or ``[x, y, θ,
    v, ω]``) behind ``leader``; returns it with ``e`` and ``z``."""
    s = _args.array("state", state).reshape(-1)
    if s.size not in (3, 5) or not np.all(np.isfinite(s)):
        raise ValueError(f"state must be 3 or 5 finite numbers ([x, y, θ] or [x, y, θ, v, ω]), got {s.tolist()}")
    leader = _leader(leader, ("p", "dp", "lx", "ly"))
    cmd, e, z = _echelon.law_kinematic(
        s,
        _vec(leader["p"], 2, "leader['p']"),
        _vec(leader["dp"], 2, "leader['dp']"),
        _offset(leader),
        _args.number("ke", ke),
    )
    return np.array(cmd), np.array(e), np.array(z)


def _simulation(name: str, sim: Any) -> None:
    from ._simulation import Simulation

    if not isinstance(sim, Simulation):
        raise TypeError(f"{name} must be an echelon.Simulation, got {_args.describe(sim)}")


def commands(sim: Any) -> np.ndarray:
    """Every agent's command now, ``(n, 2)``, each from its own law (the
    paper's, complete or kinematic) on what its controller senses, leaders
    first: what ``echelon run`` computes at a controller sample."""
    _simulation("sim", sim)
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
    _simulation("sim", sim)
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
