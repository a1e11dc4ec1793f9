"""The pieces on arrays: the safety filter over randomized crossings,
Theorem 2 both ways, identification, the batch engine."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import echelon
from conftest import builtin_document, counts_while


def unicycle(poses: np.ndarray, cmd: np.ndarray, dt: float) -> np.ndarray:
    """Exact motion of unicycles at constant (v, ω) for dt."""
    x, y, th = poses.T
    v, w = cmd.T
    small = np.abs(w) < 1e-9
    w_safe = np.where(small, 1.0, w)
    nth = th + w * dt
    nx = np.where(small, x + v * dt * np.cos(th), x + v / w_safe * (np.sin(nth) - np.sin(th)))
    ny = np.where(small, y + v * dt * np.sin(th), y - v / w_safe * (np.cos(nth) - np.cos(th)))
    return np.stack([nx, ny, nth], axis=1)


def crossing(seed_values, radius=0.3, l=0.1, dt=0.01, steps=700):
    """Four velocity robots from the corners of a square (jittered) to the
    opposite corners, go-to-goal on their points l ahead, filtered; the
    smallest distance between two points over the run."""
    size, speed, jitter = seed_values[:3]
    rng = np.random.default_rng(int(seed_values[3]))
    corners = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]], dtype=float) * size
    start = corners + rng.uniform(-jitter, jitter, size=(4, 2))
    goal = -corners + rng.uniform(-jitter, jitter, size=(4, 2))
    heading = np.arctan2(goal[:, 1] - start[:, 1], goal[:, 0] - start[:, 0]) + rng.uniform(-0.3, 0.3, 4)
    poses = np.column_stack([start, heading])
    f = echelon.safety.Filter(4, radius, l=l, period=dt)
    closest = math.inf
    for k in range(steps):
        pts = echelon.safety.points(poses, l)
        d = pts[:, None, :] - pts[None, :, :]
        dist = np.hypot(d[..., 0], d[..., 1])[~np.eye(4, dtype=bool)]
        closest = min(closest, dist.min())
        # Nominal: the point straight at its goal at up to `speed`.
        want = goal - pts
        norm = np.linalg.norm(want, axis=1, keepdims=True)
        want = want * np.minimum(1.0, speed / np.maximum(norm, 1e-12))
        c, s = np.cos(poses[:, 2]), np.sin(poses[:, 2])
        nominal = np.column_stack([c * want[:, 0] + s * want[:, 1], (-s * want[:, 0] + c * want[:, 1]) / l])
        safe = f(poses, nominal, t=k * dt)
        poses = unicycle(poses, safe, dt)
    return closest, poses


@settings(max_examples=12, deadline=None)
@given(
    size=st.floats(0.8, 1.6),
    speed=st.floats(0.2, 0.6),
    jitter=st.floats(0.0, 0.2),
    seed=st.integers(0, 2**32 - 1),
)
def test_the_filter_keeps_a_four_robot_crossing_apart(size, speed, jitter, seed):
    radius = 0.3
    closest, _ = crossing((size, speed, jitter, seed), radius=radius)
    assert closest >= radius - 1e-3, closest


def test_unfiltered_the_same_crossing_collides():
    # The property above is not vacuous: the nominal commands alone meet.
    size, speed, l, dt = 1.0, 0.4, 0.1, 0.01
    corners = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]], dtype=float) * size
    poses = np.column_stack([corners, np.arctan2(-corners[:, 1], -corners[:, 0])])
    closest = math.inf
    for _ in range(700):
        pts = echelon.safety.points(poses, l)
        d = pts[:, None, :] - pts[None, :, :]
        closest = min(closest, np.hypot(d[..., 0], d[..., 1])[~np.eye(4, dtype=bool)].min())
        poses = unicycle(poses, np.tile([speed, 0.0], (4, 1)), dt)
    assert closest < 0.05


def test_the_filter_keeps_clear_of_obstacles_and_refuses_bad_settings():
    f = echelon.safety.filter(
        [[0.0, 0.0, 0.0]], [[1.0, 0.0]], radius=0.2, obstacles=[[0.5, 0.0, 0.1]]
    )
    assert f.shape == (1, 2) and f[0, 0] < 1.0
    with pytest.raises(ValueError, match="radius"):
        echelon.safety.filter([[0.0, 0.0, 0.0]], [[1.0, 0.0]], radius=-1.0)
    with pytest.raises(ValueError, match="shape"):
        echelon.safety.filter([[0.0, 0.0, 0.0]], [[1.0, 0.0, 3.0]], radius=0.2)


@given(
    ke=st.floats(0.1, 10), kz=st.floats(0.1, 50), zeta=st.floats(1e-7, 1e-3),
    omega=st.floats(0, 3), gamma=st.floats(0.01, 0.99), n=st.integers(1, 10_000),
)
def test_theorem_2_both_ways(ke, kz, zeta, omega, gamma, n):
    fwd = echelon.bound(ke, zeta, kz=kz, omega_max=omega, gamma=gamma, steps=n, ts=0.01)
    closed = math.sqrt(2) * ke * n * zeta * math.hypot(kz, omega) / (kz * gamma)
    assert fwd["z_bound"] == pytest.approx(closed, rel=1e-12)
    assert fwd["e_bound"] == pytest.approx(closed / ke, rel=1e-12)
    assert fwd["fix_period_s"] == pytest.approx(0.01 * n)
    inv = echelon.bound(ke, zeta, kz=kz, omega_max=omega, gamma=gamma, max_z=fwd["z_bound"])
    # The largest N whose bound fits: n itself (up to rounding at the edge).
    assert inv["steps"] in (n - 1, n)
    assert inv["z_bound"] <= fwd["z_bound"]
    more = echelon.bound(ke, zeta, kz=kz, omega_max=omega, gamma=gamma, steps=inv["steps"] + 1)
    assert more["z_bound"] > fwd["z_bound"] * (1 - 1e-12)
    kin = echelon.bound(ke, zeta, gamma=gamma, steps=n, law="kinematic")
    assert kin["z_bound"] == pytest.approx(math.sqrt(2) * ke * n * zeta, rel=1e-12)
    assert kin["e_bound"] == pytest.approx(math.sqrt(2) * n * zeta / gamma, rel=1e-12)
    back = echelon.bound(ke, zeta, gamma=gamma, max_e=kin["e_bound"], law="kinematic")
    assert back["steps"] in (n - 1, n)


def test_bound_refuses_what_the_theorem_does_not_cover():
    with pytest.raises(ValueError, match="gamma"):
        echelon.bound(1.5, 1e-5, kz=10, omega_max=0.2, gamma=1.5, steps=10)
    with pytest.raises(ValueError, match="exactly one"):
        echelon.bound(1.5, 1e-5, kz=10, omega_max=0.2)


def test_identify_finds_table_1_from_a_run_or_its_dataframe(tmp_path):
    run = echelon.Scenario.builtin("identify-excitation", duration=20, log_dt=0).run(tmp_path / "id")
    by_dir = echelon.identify(run, agent=1, model="torque")
    t = run.trajectory
    by_frame = echelon.identify(t, agent=1, model="torque")
    params = {p["field"]: p for p in by_dir["params"]}
    truth = {"mass": 27.0, "linear_friction": 180.0, "inertia": 1.42, "angular_friction": 9.47}
    for field, value in truth.items():
        est = params[field]["estimate"]
        assert est is not None, params[field]
        assert est["value"] == pytest.approx(value, rel=0.02), field
    assert "[robots.identified]" in by_dir["robot_toml"]
    assert {p["field"] for p in by_frame["params"]} == set(params)


@pytest.mark.parametrize("drive", ["torque", "velocity"])
@pytest.mark.parametrize("topology", ["star", "chain"])
def test_the_batch_engine_writes_into_the_callers_buffer(drive, topology):
    e = echelon.BatchEngine.bench(100, topology=topology, drive=drive, dt=0.001, seed=3)
    out = np.full((e.n, 5), np.nan)
    e.states(out)
    start = out.copy()
    assert np.all(start[:, 3:] == 0.0)  # at rest
    e.run(500, out=out)
    assert e.time == pytest.approx(0.5)
    assert np.all(np.isfinite(out)) and not np.array_equal(out, start)
    again = echelon.BatchEngine.bench(100, topology=topology, drive=drive, dt=0.001, seed=3)
    other = np.empty_like(out)
    again.run(250)
    again.run(250, out=other)
    np.testing.assert_array_equal(out, other)
    with pytest.raises(ValueError, match="shape"):
        e.states(np.zeros((3, 5)))


def test_the_batch_engine_matches_the_simulator_on_a_scenario():
    doc = builtin_document("circle-pentagon")
    for a in doc["agents"]:
        a["leader"] = "reference"
    s = echelon.Scenario.from_dict(doc, duration=0.5)
    e = echelon.BatchEngine.from_scenario(s)
    out = np.empty((e.n, 5))
    e.run(500, out=out)
    run = s.run(log_dt=0)
    last = run.trajectory[run.trajectory.t == run.trajectory.t.max()]
    np.testing.assert_allclose(out[:, 0], last["x"].to_numpy(), atol=1e-9)
    np.testing.assert_allclose(out[:, 1], last["y"].to_numpy(), atol=1e-9)


def test_the_engine_releases_the_gil_while_stepping():
    # A Python thread spinning on the GIL gets nothing done while an extension
    # call holds it; it counts on while the engine steps.
    e = echelon.BatchEngine.bench(20_000, dt=0.001)
    during = counts_while(lambda: e.run(400))
    assert during > 10_000, during


@pytest.mark.parametrize(
    "args, kwargs",
    [
        (["--zeta", "1e-5", "--omega-max", "0.2", "--steps", "100"], {"kz": 10.0, "omega_max": 0.2, "steps": 100}),
        (["--zeta", "1e-5", "--omega-max", "0.2", "--max-z", "0.01"], {"kz": 10.0, "omega_max": 0.2, "max_z": 0.01}),
        (["--zeta", "1e-5", "--steps", "100", "--law", "kinematic"], {"steps": 100, "law": "kinematic"}),
        (["--zeta", "1e-5", "--max-e", "0.003", "--law", "kinematic"], {"max_e": 0.003, "law": "kinematic"}),
    ],
)
def test_bound_is_echelon_bound(echelon_cli, args, kwargs):
    import json
    import subprocess

    out = subprocess.run([str(echelon_cli), "bound", *args, "--json"], check=True, capture_output=True, text=True)
    assert echelon.bound(1.5, 1e-5, **kwargs) == json.loads(out.stdout)
