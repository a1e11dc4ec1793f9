"""Your controller, echelon's robots: a Python loop with echelon.law driving
Simulation.step reproduces `echelon run`'s trajectory."""

from __future__ import annotations

import numpy as np
import pytest

import echelon
from conftest import builtin_document, worst_position_gap


def python_loop(scenario: echelon.Scenario, hold_every: int) -> dict[float, np.ndarray]:
    """The run in Python: every `hold_every` steps each agent's law (leaders
    first) on what it senses, the commands held in between; the true poses
    at every step."""
    sim = echelon.Simulation(scenario)
    poses = {0.0: sim.poses}
    commands = np.zeros((sim.n, 2))
    while not sim.done:
        if sim.step_index % hold_every == 0:
            commands = np.zeros((sim.n, 2))
            for i in sim.order:
                a = sim.agents[i]
                leader = sim.leader(i, commands)
                if a["drive"] == "torque":
                    commands[i], _, _ = echelon.law.paper(
                        sim.sensed[i], leader, a["robot"], a["ke"], a["kz"], a["law"]
                    )
                else:
                    commands[i], _, _ = echelon.law.kinematic(sim.sensed[i], leader, a["ke"])
        sim.step(commands)
        poses[round(sim.time, 9)] = sim.poses
    return poses


def assert_reproduces(scenario: echelon.Scenario, hold_every: int) -> None:
    run = scenario.run(log_dt=0)
    poses = python_loop(scenario, hold_every)
    worst = worst_position_gap(run, poses)
    assert worst <= 1e-9, worst


def sampled_at_dt(name: str, duration: float) -> echelon.Scenario:
    doc = builtin_document(name)
    doc["sim"]["controller_period"] = doc["sim"]["dt"]
    return echelon.Scenario.from_dict(doc, duration=duration)


def test_dead_reckoning_robot_with_held_commands():
    # fix-study: T_s = 10 dt, odometry with fixes: the law sees the estimate.
    assert_reproduces(echelon.Scenario.builtin("fix-study", duration=2), hold_every=10)


def test_robot_leaders_torque_driven():
    # circle-pentagon: agents 3 and 4 follow agents 1 and 2.
    assert_reproduces(sampled_at_dt("circle-pentagon", 1.0), hold_every=1)


def test_velocity_bases_under_the_kinematic_law():
    assert_reproduces(sampled_at_dt("experiment-circle-velocity", 1.0), hold_every=1)


def test_law_commands_helper_is_the_same_loop():
    s = sampled_at_dt("circle-pentagon", 0.05)
    a, b = echelon.Simulation(s), echelon.Simulation(s)
    while not a.done:
        c = echelon.law.commands(a)
        a.step(c)
        b.step(echelon.law.commands(b))
    np.testing.assert_array_equal(a.poses, b.poses)


def test_limits_apply_to_python_commands():
    # TurtleBot 3 bases: a (v, ω) command beyond their speed and acceleration
    # limits moves them as any other beyond the limits does, within them.
    s = echelon.Scenario.builtin("turtlebot-circle", duration=0.1)
    big, bigger = echelon.Simulation(s), echelon.Simulation(s)
    assert {a["drive"] for a in big.agents} == {"velocity"}
    for _ in range(20):
        big.step(np.full((big.n, 2), 100.0))
        bigger.step(np.full((big.n, 2), 1000.0))
    np.testing.assert_array_equal(big.poses, bigger.poses)
    assert np.all(np.abs(big.poses[:, 3]) <= 0.22 + 1e-12)  # v_max of a Burger, m/s


def test_bad_commands_are_refused():
    sim = echelon.Simulation("circle-pentagon")
    with pytest.raises(ValueError, match=r"^commands must be .* of shape \(4, 2\)"):
        sim.step(np.zeros((3, 2)))
    with pytest.raises(ValueError, match="not finite"):
        sim.step(np.full((4, 2), np.nan))
    with pytest.raises(ValueError, match="agent 9"):
        sim.leader(9)


@pytest.mark.parametrize("commands", [np.zeros(8), np.zeros((2, 4, 1)), 3.0])
def test_commands_of_the_wrong_dimension_name_commands_and_change_nothing(commands):
    # They raised "dimensionality mismatch: from=1, to=2", naming nothing.
    sim = echelon.Simulation("circle-pentagon")
    before = sim.poses.copy()
    with pytest.raises(ValueError, match=r"^commands must be an array of numbers of shape \(4, 2\).*, got one of shape"):
        sim.step(commands)
    assert sim.step_index == 0
    np.testing.assert_array_equal(sim.poses, before)


@pytest.mark.parametrize("commands", [[["a", "b"]] * 4, None, [[1.0, None]] * 4, [[1.0], [1.0, 2.0]]])
def test_commands_that_are_not_numbers_name_commands(commands):
    sim = echelon.Simulation("circle-pentagon")
    with pytest.raises(TypeError, match="^commands must be an array of numbers"):
        sim.step(commands)
    assert sim.step_index == 0


def test_the_paper_law_on_a_robot_at_its_place_commands_friction_only():
    # A robot exactly at its point L ahead of the leader's target, moving with
    # it on a straight line: e = 0, z = 0, u balances friction (eq. 3): u1 = η v.
    robot = "agent1"
    v = 0.5
    leader = {"p": [1.0 + 0.3, 0.0], "dp": [v, 0.0], "ddp": [0.0, 0.0], "lx": 0.3, "ly": 0.0}
    u, e, z = echelon.law.paper([1.0, 0.0, 0.0, v, 0.0], leader, robot, ke=1.5, kz=10.0)
    np.testing.assert_allclose(e, 0.0, atol=1e-12)
    np.testing.assert_allclose(z, 0.0, atol=1e-12)
    np.testing.assert_allclose(u, [180.0 * v, 0.0], atol=1e-9)
    cmd, e, _ = echelon.law.kinematic([1.0, 0.0, 0.0], leader, ke=1.5)
    np.testing.assert_allclose(cmd, [v, 0.0], atol=1e-12)
