"""What both Numba peers share: the robot, the law's gains, the circle, and
the formation `echelon bench` draws (SplitMix64 in agent order, exactly as
`BenchFormation::members`). Plain Python: importing it compiles nothing and
sets no Numba option (its one jitted function, the reference table, compiles
at its first call)."""

from __future__ import annotations

import math

import numpy as np
from numba import njit

# Table I, agent 1 (RobotParams::AGENT1).
MASS, ETA, INERTIA, PSI = 27.0, 180.0, 1.42, 9.47
KE, KZ, L = 1.5, 10.0, 0.05
# The circle (BenchFormation::reference).
V_D, W_D = 0.5, 0.1

MASK64 = (1 << 64) - 1


class SplitMix64:
    """`echelon::rng::SplitMix64`, bit for bit."""

    def __init__(self, seed: int) -> None:
        self.state = seed & MASK64

    def next_u64(self) -> int:
        self.state = (self.state + 0x9E3779B97F4A7C15) & MASK64
        z = self.state
        z = ((z ^ (z >> 30)) * 0xBF58476D1CE4E5B9) & MASK64
        z = ((z ^ (z >> 27)) * 0x94D049BB133111EB) & MASK64
        return z ^ (z >> 31)

    def uniform(self, lo: float, hi: float) -> float:
        return lo + (hi - lo) * ((self.next_u64() >> 11) * (1.0 / (1 << 53)))


def formation(agents: int, seed: int = 1) -> dict[str, np.ndarray]:
    """`BenchFormation { agents, topology: Star, seed }.members()` as arrays:
    the state columns and each agent's constants."""
    rng = SplitMix64(seed)
    cols = {k: np.empty(agents) for k in ("x", "y", "theta", "lx", "ly_off", "g2", "delta", "eps")}
    for i in range(agents):
        cols["x"][i] = rng.uniform(-2.0, 2.0)
        cols["y"][i] = rng.uniform(-2.0, 2.0)
        cols["theta"][i] = rng.uniform(-math.pi, math.pi)
        lam = rng.uniform(0.2, 0.8)
        cols["ly_off"][i] = rng.uniform(-1.0, 1.0)
        cols["lx"][i] = lam + L

        # FitCoefficients::paper(λ): Horner from the highest power.
        def poly(c: list[float]) -> float:
            acc = 0.0
            for k in c:
                acc = acc * lam + k
            return acc

        cols["g2"][i] = 2.0 * poly([-4.0501, 9.8511, -6.2869, 1.6154, -0.0772])
        cols["eps"][i] = poly([6.9639, -14.778, 8.7458, -0.0207, 0.1361])
        cols["delta"][i] = poly([-8.3333, 15.37, -7.8889, 1.7657, -0.0311])
    cols["v"] = np.zeros(agents)
    cols["omega"] = np.zeros(agents)
    return cols


def star_class(run, reference_table, errors):
    """A peer's `Star`: the formation and its state, stepped by the peer's
    `run` over its `reference_table`, its `‖e‖` by its `errors`."""

    class Star:
        def __init__(self, agents: int, dt: float = 0.001, seed: int = 1) -> None:
            self.dt = dt
            self.f = formation(agents, seed)
            self.steps = 0

        def states(self) -> np.ndarray:
            f = self.f
            return np.stack([f["x"], f["y"], f["theta"], f["v"], f["omega"]], axis=1)

        def run(self, steps: int) -> None:
            f = self.f
            ref = reference_table(self.steps + steps, self.dt)[self.steps :]
            run(f["x"], f["y"], f["theta"], f["v"], f["omega"], f["lx"], f["ly_off"], f["g2"], f["delta"],
                f["eps"], ref, self.dt)
            self.steps += steps

        def errors(self) -> np.ndarray:
            f = self.f
            r = reference_table(self.steps + 1, self.dt)[self.steps, 0]
            return errors(f["x"], f["y"], f["theta"], f["lx"], f["ly_off"], f["g2"], f["delta"], f["eps"], r)

    return Star


@njit(cache=True)
def _sinc(x):
    if abs(x) < 1e-4:
        return 1.0 - x * x / 6.0
    return math.sin(x) / x


@njit(cache=True)
def reference_table(steps, dt):
    """The circle at `t_n`, `t_n + dt/2` and `t_{n+1}` for every step:
    `[px, py, dpx, dpy, ddpx, ddpy, V_d, ω_d]` per instant (`Circle::eval`,
    `Jet::speed`, `Jet::turn_rate`)."""
    out = np.empty((steps, 3, 8))
    for n in range(steps):
        for k in range(3):
            t = n * dt if k == 0 else (n * dt + 0.5 * dt if k == 1 else (n + 1) * dt)
            half = 0.5 * W_D * t
            chord = V_D * t * _sinc(half)
            sm, cm = math.sin(half), math.cos(half)
            s, c = math.sin(W_D * t), math.cos(W_D * t)
            dpx, dpy = V_D * c, V_D * s
            ddpx, ddpy = -V_D * W_D * s, V_D * W_D * c
            v2 = dpx * dpx + dpy * dpy
            out[n, k, 0] = chord * cm
            out[n, k, 1] = chord * sm
            out[n, k, 2] = dpx
            out[n, k, 3] = dpy
            out[n, k, 4] = ddpx
            out[n, k, 5] = ddpy
            out[n, k, 6] = math.sqrt(v2)
            out[n, k, 7] = 0.0 if v2 <= 1e-24 else (dpx * ddpy - dpy * ddpx) / v2
    return out
