"""Liveness from Python (issue trust2, item 4): ``echelon.safety.Filter``
(velocity bases) and ``echelon.safety.TorqueFilter`` (Table I's torque
robots) stepped by the caller, one filter per robot, on dense symmetric encounters
(robots on a circle swapping to the antipodes or to a random permutation of
the starts). Every robot's point reaches its goal within the bound of
``crates/echelon/tests/safety_swap.rs`` (docs/safety.md, "Dense
encounters"), and no two points come closer than the radius less 1 mm."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given, settings, strategies as st

import echelon

#: A robot has arrived when its point is this close to its goal, m.
ARRIVE = 0.02
L = 0.05


def bound(n: int, farthest: float, radius: float, speed: float) -> float:
    """The arrival-time bound, s: a free robot's time (the straight run at
    ``speed``, the approach at 1/s to within ARRIVE), a robot's diameter of
    detour per robot, and 10 s for the deadlock monitor's breaks."""
    return farthest / speed + math.log(speed / ARRIVE) + n * 2.0 * radius / speed + 10.0


def unicycle(poses: np.ndarray, cmd: np.ndarray, dt: float) -> np.ndarray:
    """Exact unicycle motion over ``dt`` at constant ``cmd`` (v, ω)."""
    x, y, th = poses[:, 0], poses[:, 1], poses[:, 2]
    v, w = cmd[:, 0], cmd[:, 1]
    nth = th + w * dt
    small = np.abs(w) < 1e-9
    w_safe = np.where(small, 1.0, w)
    nx = np.where(small, x + v * dt * np.cos(th), x + v / w_safe * (np.sin(nth) - np.sin(th)))
    ny = np.where(small, y + v * dt * np.sin(th), y - v / w_safe * (np.cos(nth) - np.cos(th)))
    return np.stack([nx, ny, nth], axis=1)


def encounter(n: int, circle: float, to: list[int]) -> tuple[np.ndarray, np.ndarray]:
    """Points of ``n`` robots evenly on a circle, robot i bound for the
    start of robot ``to[i]``."""
    a = 2 * math.pi * np.arange(n) / n
    starts = circle * np.column_stack([np.cos(a), np.sin(a)])
    return starts, starts[to]


def observe(t, pts, goals, arrival, closest):
    """Each robot's arrival time so far (its point within ARRIVE of its goal
    at ``t`` for the first time) and the smallest distance between two
    points so far."""
    n = len(pts)
    gaps = pts[:, None, :] - pts[None, :, :]
    closest = min(closest, np.hypot(gaps[..., 0], gaps[..., 1])[~np.eye(n, dtype=bool)].min())
    home = np.linalg.norm(goals - pts, axis=1) < ARRIVE
    return np.where(home & np.isinf(arrival), t, arrival), closest


def toward(pts, goals, speed):
    """The point velocity each robot asks for: toward its goal at 1/s, at
    most ``speed`` (Robotarium's single-integrator position controller)."""
    want = goals - pts
    norm = np.linalg.norm(want, axis=1, keepdims=True)
    return want * np.minimum(1.0, speed / np.maximum(norm, 1e-12))


def swap(starts, goals, radius, speed, *, dt=0.02, five=False, duration=None):
    """Runs the encounter with a Filter stepped every ``dt`` (poses ``(n,
    3)``, or ``(n, 5)`` with the commands last sent when ``five``): each
    robot's arrival time (inf: never) and the smallest distance between two
    points."""
    n = len(starts)
    farthest = float(np.max(np.linalg.norm(goals - starts, axis=1)))
    duration = duration or bound(n, farthest, radius, speed) + 5.0
    d = goals - starts
    heading = np.where(np.linalg.norm(d, axis=1) > 1e-9, np.arctan2(d[:, 1], d[:, 0]), np.arctan2(-starts[:, 1], -starts[:, 0]))
    poses = np.column_stack([starts - L * np.column_stack([np.cos(heading), np.sin(heading)]), heading])
    f = echelon.safety.Filter(n, radius, gain=1.0, l=L, period=dt)
    sent = np.zeros((n, 2))
    arrival = np.full(n, math.inf)
    closest = math.inf
    for k in range(int(round(duration / dt)) + 1):
        t = k * dt
        pts = echelon.safety.points(poses, L)
        arrival, closest = observe(t, pts, goals, arrival, closest)
        if np.all(np.isfinite(arrival)):
            break
        # Robotarium's single-integrator position controller on the points,
        # mapped to unicycles (si_to_uni for the point L ahead).
        want = toward(pts, goals, speed)
        c, s = np.cos(poses[:, 2]), np.sin(poses[:, 2])
        nominal = np.column_stack([c * want[:, 0] + s * want[:, 1], (-s * want[:, 0] + c * want[:, 1]) / L])
        seen = np.hstack([poses, sent]) if five else poses
        sent = f(seen, nominal, t=t)
        poses = unicycle(poses, sent, dt)
    return arrival, closest, bound(n, farthest, radius, speed)


def test_the_reported_swap_gets_everyone_home():
    # The report: 0.15 m/s, radius 0.22 m, points 5 cm ahead, the antipodal
    # swap on a 0.8 m circle, (n, 3) poses; 8 and 12 robots never arrived in
    # 60 s (a centralised QP: 43 s and 40 s).
    for n in (4, 8, 12):
        starts, goals = encounter(n, 0.8, [(i + n // 2) % n for i in range(n)])
        arrival, closest, limit = swap(starts, goals, 0.22, 0.15, duration=60.0)
        assert np.all(arrival <= min(limit, 60.0)), (n, arrival, limit)
        assert closest >= 0.22 - 1e-3, (n, closest)


#: The dense encounters drawn: N 4–16 robots on a circle `size` times the
#: smallest they fit on, to the antipodes or to a random permutation.
ENCOUNTERS = dict(
    n=st.integers(4, 16),
    size=st.floats(1.0, 2.0),
    radius=st.floats(0.15, 0.3),
    speed=st.floats(0.1, 0.3),
    antipodal=st.booleans(),
    seed=st.integers(0, 2**32 - 1),
)


def drawn(n, size, radius, antipodal, seed):
    """The starts and goals of a drawn encounter: N robots on a circle
    `size` times the smallest they fit on (circumference N · 2 radius, 10 %
    to spare), to the antipodes or to a random permutation of the starts."""
    circle = size * 1.1 * n * 2 * radius / (2 * math.pi)
    to = [(i + n // 2) % n for i in range(n)] if antipodal else list(np.random.default_rng(seed).permutation(n))
    starts, goals = encounter(n, circle, to)
    if antipodal and n % 2:
        goals = -starts
    return starts, goals


@settings(max_examples=40, deadline=None, derandomize=True)
@given(five=st.booleans(), **ENCOUNTERS)
def test_everyone_gets_home_from_python(n, size, radius, speed, antipodal, five, seed):
    # Poses (n, 3) or (n, 5).
    starts, goals = drawn(n, size, radius, antipodal, seed)
    arrival, closest, limit = swap(starts, goals, radius, speed, five=five)
    assert np.all(arrival <= limit), (arrival, limit)
    assert closest >= radius - 1e-3, closest


def torque_swap(starts, goals, radius, speed, *, dt=0.005):
    """The same encounter on Table I's torque-driven robots (eq. 3) with a
    :class:`echelon.safety.TorqueFilter` stepped every ``dt``: the point's
    velocity brought to the capped point-to-goal one at 5/s (the torques
    solved from eq. 3), the filter given the states ``(n, 5)``, the plant
    stepped by RK4. Each robot's arrival time, the smallest distance between
    two points, and the bound."""
    import json

    robot = json.loads(echelon._echelon.robot_preset("agent1"))
    m, j = robot["mass"], robot["inertia"]
    eta, psi = robot["linear_friction"], robot["angular_friction"]
    n = len(starts)
    farthest = float(np.max(np.linalg.norm(goals - starts, axis=1)))
    limit = bound(n, farthest, radius, speed)
    d = goals - starts
    heading = np.where(np.linalg.norm(d, axis=1) > 1e-9, np.arctan2(d[:, 1], d[:, 0]), np.arctan2(-starts[:, 1], -starts[:, 0]))
    states = np.column_stack([starts - L * np.column_stack([np.cos(heading), np.sin(heading)]), heading, np.zeros((n, 2))])
    f = echelon.safety.TorqueFilter(n, radius, robot="agent1", gain=1.0, l=L)

    def deriv(s, u):
        th, v, w = s[:, 2], s[:, 3], s[:, 4]
        return np.column_stack([v * np.cos(th), v * np.sin(th), w, (u[:, 0] - eta * v) / m, (u[:, 1] - psi * w) / j])

    arrival = np.full(n, math.inf)
    closest = math.inf
    for k in range(int(round((limit + 5.0) / dt)) + 1):
        t = k * dt
        pts = echelon.safety.points(states, L)
        arrival, closest = observe(t, pts, goals, arrival, closest)
        if np.all(np.isfinite(arrival)):
            break
        want = toward(pts, goals, speed)
        th, v, w = states[:, 2], states[:, 3], states[:, 4]
        c, s = np.cos(th), np.sin(th)
        now = np.column_stack([v * c - L * w * s, v * s + L * w * c])
        acc = 5.0 * (want - now)
        along = -eta * v / m - L * w * w
        across = v * w - L * psi * w / j
        r = acc - np.column_stack([along * c - across * s, along * s + across * c])
        x = np.column_stack([c * r[:, 0] + s * r[:, 1], -s * r[:, 0] + c * r[:, 1]])
        u = f(states, np.column_stack([m * x[:, 0], j * x[:, 1] / L]), t=t)
        k1 = deriv(states, u)
        k2 = deriv(states + 0.5 * dt * k1, u)
        k3 = deriv(states + 0.5 * dt * k2, u)
        k4 = deriv(states + dt * k3, u)
        states = states + dt / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)
    return arrival, closest, limit


@settings(max_examples=6, deadline=None, derandomize=True)
@given(**ENCOUNTERS)
def test_torque_robots_get_home_from_python(n, size, radius, speed, antipodal, seed):
    # The same encounters on torque-driven robots, the TorqueFilter stepped
    # from Python: every robot home within the bound, the radius kept to 1 mm
    # (each robot's neighbours take what it could not of its half of their
    # barrier, from its acceleration under what its filter last answered).
    starts, goals = drawn(n, size, radius, antipodal, seed)
    arrival, closest, limit = torque_swap(starts, goals, radius, speed)
    assert np.all(arrival <= limit), (arrival, limit)
    assert closest >= radius - 1e-3, closest
