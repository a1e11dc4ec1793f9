"""The plain Numba peer of `echelon bench --topology star --drive torque`,
kept for the record: libm's `sin`, `cos`, `atan` in every stage, one agent at
a time. `numba_star.py` is the strong one that `run.py` times by default.

The same formation, model, law and integrator as echelon's batch engine
(crates/echelon/src/engine/): Table I agent 1 (eq. 3), the paper's law
(eqs. 7-13, `K_e = 1.5`, `K_z = 10`, `L = 0.05 m`), `L_Ycomp` by eq. 6 with
`L̇_Y = L̈_Y = 0`, classical RK4 with the law evaluated in every stage, a
circular virtual leader (`V_d = 0.5 m/s`, `ω_d = 0.1 rad/s`, from the origin
along x), random starts at rest drawn from SplitMix64(seed) in agent order
exactly as `BenchFormation::members` draws them.

Written the way a good Numba user would: structure of arrays, the reference
evaluated once per stage instant for everyone (a table of steps x 3 instants:
`t_n`, `t_n + dt/2`, `t_{n+1}`, as echelon's `fill_reference` does), and
`prange` over the agents outside the time loop (a star's agents are
independent, so each thread integrates its agents through all the steps, the
state in registers), `fastmath=True` (FMA, reassociation). `sin`, `cos`,
`atan` are libm's (what Numba calls); eq. 6 is its three `atan`s as the paper
writes it (`lycomp::fit`).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from formation import ETA, INERTIA, KE, KZ, MASS, PSI, V_D, W_D, L, formation, reference_table, star_class  # noqa: F401


@njit(fastmath=True, cache=True)
def _ly(ly_off, g2, delta, eps, vd, wd):
    """`L_Yoff + L_Ycomp`, eq. 6 (`lycomp::fit`)."""
    if wd == 0.0:
        return ly_off
    rc = vd / wd
    inv = 1.0 / delta
    return ly_off + (2.0 * math.atan(rc * inv) - math.atan((rc - eps) * inv) - math.atan((rc + eps) * inv)) * g2


@njit(fastmath=True, cache=True)
def _deriv(x, y, th, v, w, r, lx, ly):
    """Eqs. 7-13 (paper variant, `L̇_Y = L̈_Y = 0`) and eq. 3: the state
    derivative at one stage, given the reference row `r`."""
    s, c = math.sin(th), math.cos(th)
    ax, ay = x - r[0], y - r[1]
    e0 = c * ax + s * ay + lx
    e1 = -s * ax + c * ay + ly
    rdp0 = c * r[2] + s * r[3]
    rdp1 = -s * r[2] + c * r[3]
    z0 = v - w * ly - rdp0 + KE * e0
    z1 = w * lx - rdp1 + KE * e1
    de0 = w * e1 + z0 - KE * e0
    de1 = -w * e0 + z1 - KE * e1
    h0 = ly * (PSI / INERTIA) * w - v * (ETA / MASS) - w * rdp1 + KE * de0
    h1 = -lx * (PSI / INERTIA) * w + w * rdp0 + KE * de1
    rddp0 = c * r[4] + s * r[5]
    rddp1 = -s * r[4] + c * r[5]
    w0 = -(h0 - rddp0) - KZ * z0
    w1 = -(h1 - rddp1) - KZ * z1
    u0 = (w0 + w1 * ly / lx) * MASS
    u1 = w1 * INERTIA / lx
    return v * c, v * s, w, (u0 - ETA * v) / MASS, (u1 - PSI * w) / INERTIA


@njit(parallel=True, fastmath=True, cache=True)
def run(x, y, th, v, w, lx, ly_off, g2, delta, eps, ref, dt):
    """`ref.shape[0]` RK4 steps of every agent, in place."""
    steps = ref.shape[0]
    for i in prange(x.shape[0]):
        xi, yi, ti, vi, wi = x[i], y[i], th[i], v[i], w[i]
        lxi = lx[i]
        # Stage 4's instant is the next step's stage 1: one L_Y serves both.
        ly2 = _ly(ly_off[i], g2[i], delta[i], eps[i], ref[0, 0, 6], ref[0, 0, 7])
        for n in range(steps):
            r0, r1, r2 = ref[n, 0], ref[n, 1], ref[n, 2]
            ly0 = ly2
            ly1 = _ly(ly_off[i], g2[i], delta[i], eps[i], r1[6], r1[7])
            ly2 = _ly(ly_off[i], g2[i], delta[i], eps[i], r2[6], r2[7])
            k1 = _deriv(xi, yi, ti, vi, wi, r0, lxi, ly0)
            h = 0.5 * dt
            k2 = _deriv(xi + h * k1[0], yi + h * k1[1], ti + h * k1[2], vi + h * k1[3], wi + h * k1[4], r1, lxi, ly1)
            k3 = _deriv(xi + h * k2[0], yi + h * k2[1], ti + h * k2[2], vi + h * k2[3], wi + h * k2[4], r1, lxi, ly1)
            k4 = _deriv(xi + dt * k3[0], yi + dt * k3[1], ti + dt * k3[2], vi + dt * k3[3], wi + dt * k3[4], r2, lxi, ly2)
            h6 = dt / 6.0
            xi += h6 * (k1[0] + 2.0 * (k2[0] + k3[0]) + k4[0])
            yi += h6 * (k1[1] + 2.0 * (k2[1] + k3[1]) + k4[1])
            ti += h6 * (k1[2] + 2.0 * (k2[2] + k3[2]) + k4[2])
            vi += h6 * (k1[3] + 2.0 * (k2[3] + k3[3]) + k4[3])
            wi += h6 * (k1[4] + 2.0 * (k2[4] + k3[4]) + k4[4])
        x[i], y[i], th[i], v[i], w[i] = xi, yi, ti, vi, wi


@njit(fastmath=True, cache=True)
def errors(x, y, th, lx, ly_off, g2, delta, eps, r):
    """Every agent's `‖e‖` (eq. 7) against the reference row `r`."""
    out = np.empty(x.shape[0])
    for i in range(x.shape[0]):
        ly = _ly(ly_off[i], g2[i], delta[i], eps[i], r[6], r[7])
        s, c = math.sin(th[i]), math.cos(th[i])
        ax, ay = x[i] - r[0], y[i] - r[1]
        e0 = c * ax + s * ay + lx[i]
        e1 = -s * ax + c * ay + ly
        out[i] = math.sqrt(e0 * e0 + e1 * e1)
    return out


Star = star_class(run, reference_table, errors)
