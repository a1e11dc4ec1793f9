"""echelon.envs (issue learn): Gymnasium and PettingZoo contracts, the
baseline against `echelon run`, the filter's radius under random actions,
and bad input refused with nothing changed."""

from __future__ import annotations

import numpy as np
import pytest

# Not importorskip: scripts/test installs both (scripts/requirements-python.txt),
# and a missing one must fail the suite, not skip what it checks.
import gymnasium
from gymnasium.utils.env_checker import check_env
from pettingzoo.test import parallel_api_test, parallel_seed_test

import echelon
from echelon import envs


def test_the_single_environment_passes_gymnasiums_check_env():
    check_env(envs.FormationEnv(4, seed=1), skip_render_check=True)


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
def test_vector_spaces_shapes_and_dtypes(dtype):
    env = envs.FormationVecEnv(3, 4, dtype=dtype, neighbours=2, seed=5)
    d = 10 + 3 * 2
    assert env.single_observation_space.shape == (4, d)
    assert env.observation_space.shape == (3, 4, d)
    assert env.action_space.shape == (3, 4, 2)
    assert env.metadata["autoreset_mode"] == gymnasium.vector.AutoresetMode.NEXT_STEP
    obs, info = env.reset(seed=2)
    assert obs.dtype == dtype and obs.shape == (3, 4, d) and env.observation_space.contains(obs)
    # Actions of another float dtype are converted.
    other = np.float32 if dtype == np.float64 else np.float64
    obs, r, term, trunc, info = env.step(env.action_space.sample().astype(other))
    assert obs.dtype == dtype and r.shape == (3,) and r.dtype == dtype
    assert term.shape == trunc.shape == (3,) and term.dtype == trunc.dtype == np.bool_
    assert info["agent_rewards"].shape == (3, 4) and info["min_distance"].shape == (3,)
    assert env.poses.shape == (3, 4, 3)


def test_seeding_is_deterministic_and_a_masked_reset_leaves_the_others_untouched():
    def rollout(seed):
        env = envs.FormationVecEnv(4, 3, seed=0)
        env.action_space.seed(seed)
        out = [env.reset(seed=seed)[0]]
        for _ in range(5):
            out.append(env.step(env.action_space.sample())[0])
        return np.stack(out), env

    a, env = rollout(11)
    b, _ = rollout(11)
    c, _ = rollout(12)
    assert np.array_equal(a, b) and not np.array_equal(a, c)
    before = env.poses
    obs_before = env.step(np.zeros((4, 3, 2)))[0].copy()
    poses = env.poses
    mask = np.array([False, True, False, True])
    obs, _ = env.reset(options={"reset_mask": mask})
    after = env.poses
    assert np.array_equal(after[~mask], poses[~mask]) and np.array_equal(obs[~mask], obs_before[~mask])
    assert not np.array_equal(after[mask], poses[mask])
    assert before.shape == after.shape


def test_autoreset_is_next_step():
    env = envs.FormationVecEnv(2, 3, max_steps=3, seed=4)
    env.reset(seed=4)
    zero = np.zeros((2, 3, 2))
    for k in range(1, 4):
        obs, r, term, trunc, _ = env.step(zero)
        assert list(trunc) == [k == 3, k == 3] and not term.any()
    obs, r, term, trunc, _ = env.step(np.full((2, 3, 2), 0.3))
    assert not trunc.any() and np.all(r == 0.0)
    # A fresh episode: at rest, where its start is.
    assert np.all(obs[..., 2:4] == 0.0)


def test_pettingzoo_api_and_seed_tests_pass():
    parallel_api_test(envs.FormationParallelEnv(4, max_steps=30, seed=3), num_cycles=40)
    parallel_seed_test(lambda: envs.FormationParallelEnv(4, max_steps=30))
    env = envs.FormationParallelEnv(3, seed=1)
    env.reset(options={"something_else": 1})  # ignored, as PettingZoo's test does
    with pytest.raises(ValueError, match="reset_mask"):
        env.reset(options={"reset_mask": "yes"})


@pytest.mark.parametrize("seed", [0, 1, 2, 3, 4])
def test_the_baseline_brings_every_robot_to_its_slot(seed):
    rng = np.random.default_rng(seed)
    env = envs.FormationVecEnv(
        int(rng.integers(1, 6)), int(rng.integers(1, 9)), spacing=float(rng.uniform(0.8, 3.0)), max_steps=10_000, seed=seed
    )
    policy = envs.baseline_policy(env)
    obs, _ = env.reset(seed=seed)
    for _ in range(800):
        obs = env.step(policy(obs))[0]
    assert np.hypot(obs[..., 0], obs[..., 1]).max() < 0.01


def test_the_baseline_through_the_env_reproduces_echelon_run():
    """The same formation as a scenario (a circle reference, the kinematic
    law held for one step, the same base): `echelon run`'s poses and the
    environment's under the baseline agree to 1e-9 m over 10 s."""
    dt, n, ke, l = 0.01, 4, 1.0, 0.1
    env = envs.FormationVecEnv(1, n, dt=dt, seed=21, max_steps=100_000, l=l)
    obs, _ = env.reset(seed=21)
    heading, speed, turn = env.leaders[0]
    offsets, starts = env.offsets[0], env.poses[0]
    doc = {
        "name": "env",
        "sim": {"duration": 10.0, "dt": dt, "controller_period": dt},
        "log": {"dt": 0.0},
        "control": {"law": "kinematic", "ke": ke, "l": l, "lycomp": "none"},
        "robots": {"r": {"drive": "velocity", "preset": "ideal", "v_max": 0.5, "omega_max": 2.0}},
        "reference": {"circle": {"speed": float(speed), "turn_rate": float(turn), "start": {"x": 0.0, "y": 0.0, "theta": float(heading)}}},
        "agents": [
            {
                "robot": "r",
                "leader": "reference",
                "start": {"x": float(s[0]), "y": float(s[1]), "theta": float(s[2])},
                "offset": {"x": float(o[0] - l), "y": float(o[1])},
            }
            for s, o in zip(starts, offsets)
        ],
    }
    run = echelon.Scenario.from_dict(doc).run()
    traj = run.trajectory
    policy = envs.baseline_policy(env, ke=ke)
    for _ in range(1000):
        obs = env.step(policy(obs))[0]
    last = traj[np.isclose(traj["t"], 10.0)].sort_values("agent")
    got = env.poses[0]
    assert len(last) == n
    assert np.abs(last["x"].to_numpy() - got[:, 0]).max() < 1e-9
    assert np.abs(last["y"].to_numpy() - got[:, 1]).max() < 1e-9


def test_the_filter_keeps_the_radius_under_random_actions_and_without_it_not():
    closest = {}
    for safety in (True, False):
        env = envs.FormationVecEnv(8, 6, spacing=0.5, radius=0.3, safety=safety, seed=9)
        assert env.safety_radius == 0.3
        env.reset(seed=9)
        env.action_space.seed(9)
        low = np.inf
        for _ in range(300):
            _, _, _, _, info = env.step(env.action_space.sample())
            low = min(low, info["min_distance"].min())
            if safety:
                assert info["safety"].shape == (8, 6) and (info["safety"] >= 0).all()
        closest[safety] = low
    assert closest[True] >= 0.3 - 1e-3, closest
    assert closest[False] < 0.3, closest


def test_bad_input_raises_and_changes_nothing():
    env = envs.FormationVecEnv(2, 3, seed=1)
    env.reset(seed=1)
    poses = env.poses
    bad = np.zeros((2, 3, 2))
    bad[1, 2, 0] = np.nan
    for actions, error in [
        (np.zeros((2, 3)), ValueError),
        (np.zeros((3, 3, 2)), ValueError),
        (bad, ValueError),
        (np.full((2, 3, 2), "a"), TypeError),
    ]:
        with pytest.raises(error):
            env.step(actions)
        assert np.array_equal(env.poses, poses)
    for options in ({"reset_mask": np.array([True])}, {"reset_mask": [1, 0]}, {"mask": np.array([True, True])}):
        with pytest.raises(ValueError):
            env.reset(options=options)
        assert np.array_equal(env.poses, poses)
    with pytest.raises(ValueError, match="model"):
        envs.FormationVecEnv(1, 2, model="quadrotor")
    with pytest.raises(Exception, match="dt"):
        envs.FormationVecEnv(1, 2, dt=-1.0)


def test_bench_measures_agent_steps_per_second():
    assert envs.bench(10, 3, steps=5) > 0.0


@pytest.mark.parametrize("dt", [0.01, 0.05])
def test_torque_robots_under_the_baseline_reach_their_slots(dt):
    env = envs.FormationVecEnv(3, 5, model="torque", dt=dt, max_steps=10_000, seed=6)
    assert env.single_action_space.high.tolist() == [[10.0, 10.0]] * 5
    policy = envs.baseline_policy(env)
    obs, _ = env.reset(seed=6)
    for _ in range(int(round(30.0 / dt))):
        obs = env.step(policy(obs))[0]
    assert np.hypot(obs[..., 0], obs[..., 1]).max() < 0.01


def test_torque_robots_keep_the_radius_under_random_torques():
    env = envs.FormationVecEnv(6, 5, model="torque", dt=0.01, spacing=0.5, radius=0.3, safety=True, seed=2)
    env.reset(seed=2)
    env.action_space.seed(2)
    low = np.inf
    for _ in range(400):
        low = min(low, env.step(env.action_space.sample())[4]["min_distance"].min())
    assert low >= 0.3 - 1e-3


def test_the_parallel_env_on_torque_robots_passes_the_api_test():
    parallel_api_test(envs.FormationParallelEnv(3, model="torque", dt=0.01, max_steps=20, seed=1), num_cycles=30)


def _doc(n=4, dt=0.01, law="kinematic"):
    robots = (
        {"r": {"drive": "velocity", "preset": "ideal", "v_max": 0.5, "omega_max": 2.0}}
        if law == "kinematic"
        else {"r": {"preset": "agent1", "torque_limit": 10.0}}
    )
    control = {"law": law, "ke": 1.0 if law == "kinematic" else 1.5, "l": 0.1, "lycomp": "none"}
    if law != "kinematic":
        control["kz"] = 10.0
    return {
        "name": "from-scenario",
        "sim": {"duration": 8.0, "dt": dt, "controller_period": dt},
        "log": {"dt": 0.0},
        "control": control,
        "robots": robots,
        "reference": {"circle": {"speed": 0.15, "turn_rate": 0.05, "start": {"x": 0.0, "y": 0.0, "theta": 0.3}}},
        "agents": [
            {
                "robot": "r",
                "leader": "reference",
                "start": {"x": -1.0 - 0.8 * i, "y": 0.5 * (-1) ** i, "theta": 0.1 * i},
                "offset": {"x": 0.9 + 0.8 * i, "y": 0.4 * (-1) ** i},
            }
            for i in range(n)
        ],
    }


@pytest.mark.parametrize("law", ["kinematic", "complete"])
def test_an_environment_from_a_scenario_under_the_baseline_is_echelon_run(law):
    """`scenario=`: every episode is the scenario's formation, and the
    baseline through the environment is `echelon run` of it (1e-9 m for the
    kinematic law; the complete law's torques make a round trip through the
    wheels, 1e-7 m)."""
    doc = _doc(law=law)
    sc = echelon.Scenario.from_dict(doc)
    env = envs.FormationVecEnv(2, 4, scenario=sc, max_steps=100_000, seed=1)
    assert env.dtype == np.float64 and env._core.dt == 0.01
    assert env._core.model == ("unicycle" if law == "kinematic" else "torque")
    policy = envs.baseline_policy(env, ke=doc["control"]["ke"])
    obs, _ = env.reset(seed=1)
    assert np.array_equal(env.poses[0], env.poses[1])
    for _ in range(800):
        obs = env.step(policy(obs))[0]
    traj = sc.run().trajectory
    last = traj[np.isclose(traj["t"], 8.0)].sort_values("agent")
    tol = 1e-9 if law == "kinematic" else 1e-7
    for k in range(2):
        assert np.abs(last["x"].to_numpy() - env.poses[k][:, 0]).max() < tol
        assert np.abs(last["y"].to_numpy() - env.poses[k][:, 1]).max() < tol


def test_a_scenario_the_environments_do_not_model_is_refused():
    with pytest.raises(ValueError, match="L_Ycomp|lycomp"):
        envs.FormationVecEnv(1, 5, scenario="lemniscate-wedge")
    with pytest.raises(ValueError, match="number of agents"):
        envs.FormationVecEnv(1, 3, scenario=echelon.Scenario.from_dict(_doc(n=4)))


def test_observation_spaces_bound_the_listed_flags_and_the_parallel_env_has_a_state():
    env = envs.FormationVecEnv(2, 3, neighbours=2, seed=0)
    space = env.single_observation_space
    assert space.low[0, 12] == 0.0 and space.high[0, 12] == 1.0 and space.high[0, 15] == 1.0
    assert np.isinf(space.low[0, 0]) and np.isinf(space.high[0, 11])
    par = envs.FormationParallelEnv(3, neighbours=2, seed=0)
    obs, _ = par.reset(seed=0)
    state = par.state()
    assert par.state_space.contains(state)
    assert np.array_equal(state, np.concatenate([obs[a] for a in par.possible_agents]))


def _edges(env, k):
    """Environment ``k``'s distances from each robot's point to each
    obstacle's edge, ``(N, M)``, from its poses and obstacles."""
    p = envs._points(env.poses[k], env._core.l)
    o = env.obstacles[k]
    return np.linalg.norm(p[:, None, :] - o[None, :, :2], axis=-1) - o[None, :, 2]


@pytest.mark.parametrize("seed", [0, 7, 123])
def test_obstacles_are_drawn_clear_of_the_starts_and_observed_nearest_first(seed):
    m, k = 6, 2
    env = envs.FormationVecEnv(5, 7, spacing=0.7, obstacles=m, obstacle_radius=(0.1, 0.5), neighbours=k, seed=seed)
    obs, _ = env.reset(seed=seed)
    assert env.obs_dim == 10 + 3 * k + 4 * 4  # all obstacles up to 4 listed by default
    obstacles = env.obstacles
    assert obstacles.shape == (5, m, 3)
    assert ((0.1 <= obstacles[..., 2]) & (obstacles[..., 2] <= 0.5)).all()
    plain = envs.FormationVecEnv(5, 7, spacing=0.7, neighbours=k, seed=seed)
    plain.reset(seed=seed)
    assert np.array_equal(plain.poses, env.poses), "obstacles leave the formation's draw as it was"
    for e in range(5):
        assert _edges(env, e).min() >= env.safety_radius - 1e-12, f"env {e}: an edge within the radius of a start"
    env.action_space.seed(seed)
    for _ in range(20):
        obs, _, _, _, info = env.step(env.action_space.sample())
    for e in range(5):
        edges = _edges(env, e)
        assert np.isclose(info["obstacle_distance"][e], edges.min(), rtol=0, atol=1e-12)
        p = envs._points(env.poses[e], env._core.l)
        for i in range(7):
            order = [j for j in np.argsort(edges[i], kind="stable") if edges[i, j] <= 3.0 * 0.7][:4]
            theta = env.poses[e, i, 2]
            rot = np.array([[np.cos(theta), np.sin(theta)], [-np.sin(theta), np.cos(theta)]])
            at = 10 + 3 * k
            for slot in range(4):
                got = obs[e, i, at + 4 * slot : at + 4 * slot + 4]
                if slot < len(order):
                    j = order[slot]
                    want = rot @ (obstacles[e, j, :2] - p[i])
                    assert got[3] == 1.0 and got[2] == obstacles[e, j, 2]
                    assert np.allclose(got[:2], want, rtol=0, atol=1e-9)
                else:
                    assert (got == 0).all()
    assert env.observation_space.contains(obs)


def test_the_filter_keeps_the_obstacles_clear_and_without_it_the_formation_hits_them():
    clearance = {}
    for safety in (True, False):
        env = envs.FormationVecEnv(
            6, 5, spacing=0.6, radius=0.25, obstacles=6, obstacle_radius=(0.15, 0.4), speed=(0.15, 0.2),
            max_steps=300, safety=safety, seed=3, copy=False,
        )
        policy = envs.baseline_policy(env)
        obs, _ = env.reset(seed=3)
        rng = np.random.default_rng(3)
        low = np.inf
        for _ in range(300):
            a = policy(obs) + rng.uniform([-0.1, -0.5], [0.1, 0.5], (6, 5, 2))
            obs, rewards, _, _, info = env.step(a)
            low = min(low, info["obstacle_distance"].min())
            hit = info["obstacle_distance"] < 0.25
            if hit.any() and not safety:
                # The collision term counts the obstacle.
                assert (info["agent_rewards"][hit].min(axis=-1) <= -10.0).all()
        clearance[safety] = low
    assert clearance[True] >= 0.25 - 1e-3, clearance
    assert clearance[False] < 0.25, clearance


def test_a_scenarios_obstacles_are_every_episodes():
    doc = _doc()
    doc["safety"] = {"radius": 0.2, "obstacles": [{"x": 2.0, "y": 0.6, "r": 0.3}, {"x": 3.0, "y": -0.5, "r": 0.2}]}
    sc = echelon.Scenario.from_dict(doc)
    env = envs.FormationVecEnv(2, 4, scenario=sc, seed=1)
    want = np.array([[2.0, 0.6, 0.3], [3.0, -0.5, 0.2]])
    assert env.obstacles.shape == (2, 2, 3)
    assert np.array_equal(env.obstacles[0], want) and np.array_equal(env.obstacles[1], want)
    assert env.obs_dim == 10 + 3 * 4 + 4 * 2
    with pytest.raises(ValueError, match="obstacles"):
        envs.FormationVecEnv(2, 4, scenario=sc, obstacles=3, seed=1)


@pytest.mark.parametrize(
    "kwargs, error",
    [
        ({"obstacles": -1}, ValueError),
        ({"obstacles": 2.5}, TypeError),
        ({"obstacles": 2, "obstacle_radius": (0.0, 0.3)}, ValueError),
        ({"obstacles": 2, "obstacle_radius": (0.4, 0.3)}, ValueError),
        ({"obstacles": 2, "seen_obstacles": 17}, ValueError),
        ({"seen_obstacles": -2}, ValueError),
    ],
)
def test_bad_obstacle_settings_are_refused(kwargs, error):
    with pytest.raises(error):
        envs.FormationVecEnv(2, 3, seed=0, **kwargs)


def test_obstacles_pass_gymnasiums_and_pettingzoos_checks():
    check_env(envs.FormationEnv(4, obstacles=3, max_steps=50, seed=0).unwrapped, skip_render_check=True)
    parallel_api_test(envs.FormationParallelEnv(4, obstacles=3, max_steps=20, seed=1), num_cycles=30)
    par = envs.FormationParallelEnv(4, obstacles=3, seen_obstacles=1, seed=1)
    obs, _ = par.reset(seed=1)
    assert par.observation_space("robot_0").shape == (10 + 3 * 4 + 4,)
    _, _, _, _, infos = par.step({a: np.zeros(2) for a in par.agents})
    assert np.isfinite(infos["robot_0"]["obstacle_distance"])
