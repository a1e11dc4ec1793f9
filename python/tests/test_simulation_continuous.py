"""A continuous-time controller from Python: Simulation.step_by calls the
law in every RK4 stage, where `echelon run` evaluates its own, and
reproduces the run's trajectory."""

from __future__ import annotations

import numpy as np
import pytest

import echelon
from conftest import worst_position_gap


def stepped_by(scenario: echelon.Scenario, law=None) -> dict[float, np.ndarray]:
    sim = echelon.Simulation(scenario)
    law = law or echelon.law.own(sim)
    poses = {0.0: sim.poses}
    while not sim.done:
        sim.step_by(law)
        poses[round(sim.time, 9)] = sim.poses
    return poses


def worst_gap(scenario: echelon.Scenario, law=None) -> float:
    run = scenario.run(log_dt=0)
    poses = stepped_by(scenario, law)
    return worst_position_gap(run, poses)


@pytest.mark.parametrize(
    "name, duration",
    [
        ("circle-pentagon", 1.0),  # torque, robot leaders (their v̇ at each stage)
        ("lemniscate-wedge", 1.0),  # torque, the lemniscate reference
        ("circle-pentagon-velocity", 1.0),  # velocity bases, settled at each new state
        ("turtlebot-circle", 1.0),  # velocity bases with lags and limits
    ],
)
def test_the_own_law_per_stage_reproduces_a_continuous_run(name, duration):
    assert worst_gap(echelon.Scenario.builtin(name, duration=duration)) <= 1e-9


def test_the_law_is_called_in_every_stage_with_the_stage_time():
    s = echelon.Scenario.builtin("circle-pentagon", duration=0.01)
    sim = echelon.Simulation(s)
    own = echelon.law.own(sim)
    calls = []

    def law(i, t, state, leader):
        calls.append((i, t))
        return own(i, t, state, leader)

    sim.step_by(law)
    dt = sim.dt
    # Four stages (t, t + dt/2 twice, t + dt), each agent once, leaders first.
    assert [t for _, t in calls] == [0.0] * 4 + [dt / 2] * 8 + [dt] * 4
    assert [i for i, _ in calls[:4]] == sim.order


def test_a_law_that_fails_moves_nothing():
    s = echelon.Scenario.builtin("circle-pentagon", duration=0.01)
    sim = echelon.Simulation(s)
    own = echelon.law.own(sim)
    before = sim.poses
    count = [0]

    def flaky(i, t, state, leader):
        count[0] += 1
        if count[0] == 7:  # in the second stage
            raise KeyError("boom")
        return own(i, t, state, leader)

    with pytest.raises(KeyError, match="boom"):
        sim.step_by(flaky)
    np.testing.assert_array_equal(sim.poses, before)
    assert sim.step_index == 0
    with pytest.raises(ValueError, match="not finite"):
        sim.step_by(lambda i, t, s, l: (np.nan, 0.0))
    with pytest.raises(ValueError, match="expected 2"):
        sim.step_by(lambda i, t, s, l: (1.0, 2.0, 3.0))
    np.testing.assert_array_equal(sim.poses, before)
    # Then the step goes as it would have.
    sim.step_by(own)
    ref = echelon.Simulation(s)
    ref.step_by(own)
    np.testing.assert_array_equal(sim.poses, ref.poses)


def test_a_sampled_or_filtered_scenario_is_refused():
    with pytest.raises(ValueError, match="step_with|sampled"):
        sim = echelon.Simulation("fix-study")  # controller_period = 10 dt
        sim.step_by(echelon.law.own(sim))
    sim = echelon.Simulation("circle-pentagon", duration=0.01)
    sim.step(echelon.law.commands(sim))
    with pytest.raises(ValueError, match="sampled"):
        sim.step_by(echelon.law.own(sim))
