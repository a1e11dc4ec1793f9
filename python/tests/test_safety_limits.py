"""echelon.safety.Filter on a velocity base of the caller's own: ``base`` as
a dict spelled as a scenario's ``[robots.NAME]`` velocity base (a preset
overridden field by field, or every field given), equal to a preset's when
its values are, its limits kept, bad fields refused by name."""

from __future__ import annotations

import math

import numpy as np
import pytest

import echelon

INF = float("inf")

#: The presets' lags and limits as written in crates/echelon-core/src/model/base.rs.
PRESETS = {
    "ideal": dict(tau_v=0.0, tau_omega=0.0, v_max=INF, omega_max=INF, a_max=INF, alpha_max=INF),
    "turtlebot3-burger": dict(tau_v=0.1, tau_omega=0.1, v_max=0.22, omega_max=2.84, a_max=2.5, alpha_max=3.2),
    "turtlebot4": dict(tau_v=0.1, tau_omega=0.1, v_max=0.306, omega_max=1.90, a_max=0.9, alpha_max=0.9 / 0.1175),
    "jackal": dict(tau_v=0.05, tau_omega=0.05, v_max=2.0, omega_max=4.0, a_max=20.0, alpha_max=25.0),
}


def crowd(rng: np.random.Generator, n: int, speed: float, five: bool) -> tuple[np.ndarray, np.ndarray]:
    """``n`` robots close together (their points often within the radius of
    each other) asking for random commands up to ``speed`` (m/s; ω up to
    ``4 speed`` rad/s): poses ``(n, 5)`` with random speeds when ``five``,
    else ``(n, 3)``."""
    xy = rng.uniform(-0.6, 0.6, size=(n, 2))
    theta = rng.uniform(-math.pi, math.pi, size=(n, 1))
    commands = np.column_stack([rng.uniform(-speed, speed, n), rng.uniform(-4 * speed, 4 * speed, n)])
    if not five:
        return np.hstack([xy, theta]), commands
    vw = np.column_stack([rng.uniform(-speed, speed, n), rng.uniform(-4 * speed, 4 * speed, n)])
    return np.hstack([xy, theta, vw]), commands


def run(base, seed: int, steps: int = 8) -> tuple[list[np.ndarray], list[list[str]], list[list[float]]]:
    """A filter on ``base`` fed ``steps`` random crowds (seeded) in turn,
    one every period (its deadlock monitors remember): what it gave."""
    rng = np.random.default_rng(seed)
    n = int(rng.integers(2, 6))
    five = bool(rng.integers(0, 2))
    f = echelon.safety.Filter(n, 0.3, gain=1.0, range=2.0, l=0.05, period=0.02, base=base)
    outs, outcomes, closest = [], [], []
    for k in range(steps):
        poses, commands = crowd(rng, n, float(rng.uniform(0.05, 2.5)), five)
        outs.append(f(poses, commands, t=0.02 * k))
        outcomes.append(list(f.outcomes))
        closest.append(list(f.min_distance))
    return outs, outcomes, closest


@pytest.mark.parametrize("preset", sorted(PRESETS))
def test_custom_limits_equal_to_a_presets_filter_bit_for_bit_as_the_preset(preset):
    # Every field spelled out, the preset named in a dict, and the preset
    # overridden by its own values: the same base, so the same bits.
    spelled = dict(PRESETS[preset], accel="joint")
    named = {"preset": preset}
    overridden = {"preset": preset, "drive": "velocity", "v_max": PRESETS[preset]["v_max"]}
    seen = set()
    for seed in range(40):
        want = run(preset, seed)
        for base in (spelled, named, overridden):
            got = run(base, seed)
            for w, g in zip(want[0], got[0]):
                np.testing.assert_array_equal(g, w)
            assert got[1:] == want[1:]
        seen.update(o for step in want[1] for o in step)
    # The random crowds made the filter act, not only pass the nominals.
    assert "filtered" in seen


def test_a_custom_base_differs_from_the_preset_it_overrides():
    # The overrides reach the filter: a tighter v_max changes the commands.
    want = run("jackal", 3)[0]
    got = run({"preset": "jackal", "v_max": 0.1}, 3)[0]
    assert any(not np.array_equal(w, g) for w, g in zip(want, got))


TIGHT = [
    # Ideal lags (the first-order filter): speed limits only.
    {"v_max": 0.15, "omega_max": 0.7},
    # A preset with tighter limits (the lagged filter).
    {"preset": "turtlebot4", "v_max": 0.12, "omega_max": 0.8, "a_max": 0.5, "alpha_max": 2.0},
    # Every field given, per-axis acceleration limits.
    {"tau_v": 0.2, "tau_omega": 0.15, "v_max": 0.25, "omega_max": 1.2, "a_max": 0.3, "alpha_max": 1.5, "accel": "per-axis"},
]


@pytest.mark.parametrize("base", TIGHT)
def test_a_tighter_custom_limit_bounds_the_filtered_commands(base):
    v_max, w_max = base["v_max"], base["omega_max"]
    tau_v = base.get("tau_v", PRESETS[base.get("preset", "ideal")]["tau_v"])
    tau_w = base.get("tau_omega", PRESETS[base.get("preset", "ideal")]["tau_omega"])
    a_max = base.get("a_max", PRESETS[base.get("preset", "ideal")]["a_max"])
    alpha_max = base.get("alpha_max", PRESETS[base.get("preset", "ideal")]["alpha_max"])
    tol = 1e-6
    rng = np.random.default_rng(46)
    checked = 0
    for _ in range(150):
        n = int(rng.integers(2, 6))
        f = echelon.safety.Filter(n, 0.3, gain=1.0, range=2.0, l=0.05, period=0.02, base=base)
        for k in range(4):
            # Actual speeds within the base's box (where a real base stays).
            poses, commands = crowd(rng, n, 1.0, five=True)
            poses[:, 3] = rng.uniform(-v_max, v_max, n)
            poses[:, 4] = rng.uniform(-w_max, w_max, n)
            out = f(poses, commands, t=0.02 * k)
            assert np.all(np.abs(out[:, 0]) <= v_max + tol), out
            assert np.all(np.abs(out[:, 1]) <= w_max + tol), out
            if tau_v > 0:
                # A command the filter changed keeps within what the lags
                # reach under the acceleration limits (a nominal it passes
                # goes to the base, whose own limits act on it).
                on = np.array([o == "filtered" for o in f.outcomes])
                assert np.all(np.abs(out[on, 0] - poses[on, 3]) <= tau_v * a_max + tol), (out, poses)
                assert np.all(np.abs(out[on, 1] - poses[on, 4]) <= tau_w * alpha_max + tol), (out, poses)
                checked += int(on.sum())
            else:
                checked += int(sum(o == "filtered" for o in f.outcomes))
    # The random crowds made the filter act on many robots.
    assert checked > 50


@pytest.mark.parametrize(
    "base, error, field",
    [
        ({"v_max": -0.5}, ValueError, "base.v_max"),
        ({"v_max": 0.0}, ValueError, "base.v_max"),
        ({"omega_max": float("nan")}, ValueError, "base.omega_max"),
        ({"alpha_max": -1.0, "tau_omega": 0.1}, ValueError, "base.alpha_max"),
        ({"tau_v": -0.1}, ValueError, "base.tau_v"),
        ({"tau_omega": float("nan")}, ValueError, "base.tau_omega"),
        ({"tau_v": INF}, ValueError, "base.tau_v"),
        ({"a_max": 1.0}, ValueError, "base.a_max"),  # an ideal axis has no acceleration to limit
        ({"preset": "turtlebot4", "tau_v": 0.0}, ValueError, "base.a_max"),
        ({"v_max": "fast"}, TypeError, "base.v_max"),
        ({"v_max": None}, TypeError, "base.v_max"),
        ({"v_max": True}, TypeError, "base.v_max"),
        ({"vmax": 0.5}, ValueError, "base.vmax"),
        ({"mass": 1.0}, ValueError, "base.mass"),
        ({"reverse_limit": 0.1}, ValueError, "base.reverse_limit"),
        ({"preset": "turtlebot9"}, ValueError, "base.preset"),
        ({"preset": 4}, TypeError, "base.preset"),
        ({"drive": "torque"}, ValueError, "base.drive"),
        ({"accel": "both"}, ValueError, "base.accel"),
        ({1: 0.5}, TypeError, "base"),
        ("turtlebot9", ValueError, "base"),
        (0.5, TypeError, "base"),
        (None, TypeError, "base"),
    ],
)
def test_a_bad_custom_base_is_refused_naming_its_field(base, error, field):
    with pytest.raises(error) as e:
        echelon.safety.Filter(2, 0.3, base=base)
    assert str(e.value).startswith(field), str(e.value)
    with pytest.raises(error):
        echelon.safety.filter(np.zeros((2, 3)), np.zeros((2, 2)), radius=0.3, base=base)


def test_a_mapping_not_a_dict_and_numpy_numbers_are_taken():
    from types import MappingProxyType

    base = MappingProxyType({"preset": "turtlebot4", "a_max": np.float64(0.5), "v_max": np.int64(1)})
    f = echelon.safety.Filter(2, 0.3, base=base)
    # Far apart, side by side: the nominals pass, within the overridden
    # v_max = 1 (not the preset's 0.306).
    out = f(np.array([[0.0, 0.0, 0.0], [0.0, 50.0, 0.0]]), np.array([[3.0, 0.0], [3.0, 0.0]]))
    assert f.outcomes == ["nominal", "nominal"]
    np.testing.assert_allclose(out[:, 0], [1.0, 1.0], atol=1e-12)
