"""echelon.safety for torque-driven robots (eq. 3): the torque barrier filter
on arrays keeps randomized crossings of echelon's robots apart, and is the
simulator's own filter (the same commands, step by step)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import echelon
from conftest import builtin_document


def torque_crossing(size: float, jitter: float, seed: int, radius: float, l: float, limit: float | None):
    """Four Table I robots (agent1) at the jittered corners of a square,
    `[safety]` set (used only where a test turns it on); their goals, the
    opposite corners."""
    rng = np.random.default_rng(seed)
    corners = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]], dtype=float) * size
    start = corners + rng.uniform(-jitter, jitter, size=(4, 2))
    heading = np.arctan2(-start[:, 1], -start[:, 0]) + rng.uniform(-0.2, 0.2, 4)
    robot = {"preset": "agent1"} if limit is None else {"preset": "agent1", "torque_limit": limit}
    doc = {
        "name": "torque-crossing",
        "sim": {"duration": 4.0 * size / 0.3 + 4.0, "dt": 0.01},
        "log": {"dt": 0.1},
        "control": {"law": "paper", "ke": 1.5, "kz": 10.0, "l": l, "lycomp": "none"},
        "robots": {"bot": robot},
        "reference": {"line": {"speed": 0.1, "start": {"x": 0.0, "y": 0.0, "theta": 0.0}}},
        "safety": {"radius": radius, "gain": 1.0, "range": 2.0},
        "agents": [
            {
                "name": f"T{i + 1}",
                "robot": "bot",
                "start": {"x": float(start[i, 0]), "y": float(start[i, 1]), "theta": float(heading[i])},
                "leader": "reference",
                "offset": {"x": 0.5, "y": float(i)},
            }
            for i in range(4)
        ],
    }
    return echelon.Scenario.from_dict(doc), -start


def nominal_torques(states: np.ndarray, goal: np.ndarray, robot: dict, l: float, speed: float) -> np.ndarray:
    """Naive: each point straight at its goal at up to `speed` (as a (v, ω)
    command), tracked by a proportional torque law on eq. 3."""
    x, y, th, v, w = states.T
    c, s = np.cos(th), np.sin(th)
    want = goal - np.column_stack([x + l * c, y + l * s])
    norm = np.linalg.norm(want, axis=1, keepdims=True)
    want = want * np.minimum(1.0, speed / np.maximum(norm, 1e-12))
    v_star = c * want[:, 0] + s * want[:, 1]
    w_star = (-s * want[:, 0] + c * want[:, 1]) / l
    m, eta, j, psi = robot["mass"], robot["linear_friction"], robot["inertia"], robot["angular_friction"]
    k = 6.0
    return np.column_stack([m * k * (v_star - v) + eta * v, j * k * (w_star - w) + psi * w])


def closest_points(states: np.ndarray, l: float) -> float:
    pts = echelon.safety.points(states, l)
    d = pts[:, None, :] - pts[None, :, :]
    return float(np.hypot(d[..., 0], d[..., 1])[~np.eye(len(pts), dtype=bool)].min())


def drive(scenario, goal, l, speed, filt=None) -> float:
    """The crossing stepped by the simulator (its own filter off), the
    Python-side torque filter `filt` (if any) between the law and the robots."""
    sim = echelon.Simulation(scenario, safety=False)
    robot = sim.agents[0]["robot"]
    closest = math.inf
    while not sim.done:
        closest = min(closest, closest_points(sim.poses, l))
        u = nominal_torques(sim.poses, goal, robot, l, speed)
        if filt is not None:
            u = filt(sim.poses, u, t=sim.time)
        sim.step(u)
    return closest


@settings(max_examples=6, deadline=None)
@given(
    size=st.floats(0.7, 1.3),
    speed=st.floats(0.2, 0.5),
    jitter=st.floats(0.0, 0.05),
    seed=st.integers(0, 2**32 - 1),
    limit=st.sampled_from([None, 6.0, 12.0]),
)
def test_the_torque_filter_keeps_a_crossing_of_table_1_robots_apart(size, speed, jitter, seed, limit):
    radius, l = 0.3, 0.1
    s, goal = torque_crossing(size, jitter, seed, radius, l, limit)
    robot = echelon.Simulation(s).agents[0]["robot"]
    assert robot["torque_limit"] == limit
    f = echelon.safety.TorqueFilter(4, radius, robot=robot, gain=1.0, range=2.0, l=l)
    closest = drive(s, goal, l, speed, f)
    assert closest >= radius - 1e-3, closest
    assert set(f.outcomes) <= {"nominal", "filtered", "braked"}
    # Not vacuous: unfiltered, the same torques bring the points together.
    assert drive(s, goal, l, speed) < radius - 1e-3


@settings(max_examples=4, deadline=None)
@given(
    size=st.floats(0.7, 1.3),
    jitter=st.floats(0.0, 0.1),
    seed=st.integers(0, 2**32 - 1),
    limit=st.sampled_from([None, 8.0]),
)
def test_the_torque_filter_is_the_simulators(size, jitter, seed, limit):
    # Step by step, the array filter given what the scenario's filter was
    # given (the states before the step, the nominal after the acceleration
    # limit) answers the same commands, bit for bit.
    radius, l = 0.3, 0.1
    s, goal = torque_crossing(size, jitter, seed, radius, l, limit)
    sim = echelon.Simulation(s, duration=6.0)
    robot = sim.agents[0]["robot"]
    f = echelon.safety.TorqueFilter(4, radius, robot="agent1" if limit is None else robot, gain=1.0, range=2.0, l=l)
    changed = 0
    while not sim.done:
        before, t = sim.poses, sim.time
        sim.step(nominal_torques(before, goal, robot, l, 0.4))
        report = sim.safety_step
        ours = f(before, report["nominal"], t=t)
        np.testing.assert_array_equal(ours, report["filtered"])
        assert f.outcomes == report["outcome"]
        changed += int(report["active"].sum())
    assert changed > 0


def test_the_velocity_filter_is_the_simulators_too():
    # The built-in crossing on bases without speed limits (`Filter`'s `base`
    # names a preset: `ideal` here).
    doc = builtin_document("crossing")
    doc["robots"]["base"] = {"drive": "velocity", "preset": "ideal"}
    s = echelon.Scenario.from_dict(doc, duration=8.0)
    sim = echelon.Simulation(s)
    f = echelon.safety.Filter(sim.n, 0.3, gain=1.0, range=1.5, l=0.05, period=sim.dt)
    changed = 0
    while not sim.done:
        before, t = sim.poses, sim.time
        sim.step(echelon.law.commands(sim))
        report = sim.safety_step
        np.testing.assert_array_equal(f(before, report["nominal"], t=t), report["filtered"])
        changed += int(report["active"].sum())
    assert changed > 0


def test_the_torque_filter_refuses_bad_input():
    f = echelon.safety.TorqueFilter(2, 0.3)
    with pytest.raises(ValueError, match=r"^states must be a float64 array of shape \(2, 5\), .* got .* \(2, 3\)"):
        f(np.zeros((2, 3)), np.zeros((2, 2)))
    with pytest.raises(ValueError, match=r"^commands must be a float64 array of shape \(2, 2\), .* got .* \(2, 3\)"):
        f(np.zeros((2, 5)), np.zeros((2, 3)))
    with pytest.raises(ValueError, match="not finite"):
        f(np.zeros((2, 5)), np.full((2, 2), np.inf))
    with pytest.raises(ValueError, match="states: NaN is not finite"):
        f(np.full((2, 5), np.nan), np.zeros((2, 2)))
    with pytest.raises(ValueError, match="poses: NaN is not finite"):
        echelon.safety.Filter(2, 0.3)(np.full((2, 3), np.nan), np.zeros((2, 2)))
    with pytest.raises(ValueError, match="radius"):
        echelon.safety.TorqueFilter(2, -0.3)
    with pytest.raises(ValueError, match="not a preset"):
        echelon.safety.TorqueFilter(2, 0.3, robot="agent9")
    with pytest.raises(ValueError, match="3 robots given for 2"):
        echelon.safety.TorqueFilter(2, 0.3, robot=["agent1"] * 3)
    with pytest.raises(ValueError, match="robot"):
        echelon.safety.TorqueFilter(2, 0.3, robot={"mass": 1.0})


@pytest.mark.parametrize("n", [10**9, 2**50])
def test_filters_for_more_robots_than_memory_holds_raise_memoryerror(n):
    # They used to abort the interpreter ("memory allocation of … failed").
    for make in [echelon.safety.Filter, echelon.safety.TorqueFilter]:
        with pytest.raises(MemoryError, match=f"^n: {n} robots' filters do not fit in memory"):
            make(n, 0.3)


def test_torque_filter_brakes_toward_a_neighbour_and_passes_otherwise():
    # Two robots 0.5 m apart (points 0.3 m + margin), one driving at the other
    # at 1 m/s: full forward torque is cut; driving apart passes unchanged.
    l = 0.1
    states = np.array([[0.0, 0.0, 0.0, 1.0, 0.0], [0.6, 0.0, np.pi, 0.0, 0.0]])
    push = np.array([[200.0, 0.0], [0.0, 0.0]])
    out = echelon.safety.torque_filter(states, push, radius=0.3, l=l)
    assert out[0, 0] < push[0, 0]
    away = states.copy()
    away[0, 2], away[0, 3] = np.pi, 0.1  # facing away, moving away
    np.testing.assert_array_equal(echelon.safety.torque_filter(away, push, radius=0.3, l=l), push)
    assert echelon.safety.INNER_RATE > 0 and echelon.safety.ENVELOPE["v_reverse"] == 0.0
