"""The Numba peer of `echelon bench --topology star --drive torque`.

The same formation, model, law and integrator as echelon's batch engine
(crates/echelon-core/src/engine/): Table I agent 1 (eq. 3), the paper's law
(eqs. 7-13, `K_e = 1.5`, `K_z = 10`, `L = 0.05 m`), `L_Ycomp` by eq. 6 with
`L̇_Y = L̈_Y = 0`, classical RK4 with the law evaluated in every stage, a
circular virtual leader (`V_d = 0.5 m/s`, `ω_d = 0.1 rad/s`, from the origin
along x), random starts at rest drawn from SplitMix64(seed) in agent order
exactly as `BenchFormation::members` draws them.

Written for speed, as a skilled Numba user would:

* float64 structure of arrays, in tiles of `TILE` agents: `prange` over the
  tiles, and each tile runs every step with its agents as the innermost loop,
  so the tile's state stays in L1 and LLVM vectorises the agent loop (the loop
  body is branch-free: every `if` below is a select). All four RK4 stages are
  fused in that loop. The reference is tabulated once per instant for
  everyone (steps x 3 instants: `t_n`, `t_n + dt/2`, `t_{n+1}`) and read as
  scalars outside the agent loop.
* No libm call in the loop (Numba's `math.sin` / `atan2` are scalar libm
  calls and stop the vectoriser; Intel SVML is not usable with llvmlite's
  unpatched LLVM): `sin`/`cos` by Cody-Waite reduction and Cephes'
  polynomials, `atan2` by Cephes' reduction and rational approximation, both
  within 1-2 ulp of libm.
* `sin`/`cos` of θ once per step: stages 2-4 turn them by their small
  `δθ = c·dt·ω` with the angle-sum formulas and Taylor series of `sin δ`,
  `cos δ − 1` (accurate to 1e-17 for `|δ| < 0.05`; a tile in which some stage
  turns by more redoes that step with `sin`/`cos` in every stage).
* Eq. 6's three `atan`s as one angle: `2 atan a − atan(a − k) − atan(a + k)`
  is the argument of `(1 + ia)² / ((1 + i(a − k))(1 + i(a + k)))`, i.e.
  `atan2(2ak², (1 + a²)² + k²(1 − a²))` with `a = R_C/δ`, `k = ε/δ`. Stage 4's
  instant is the next step's stage 1: two `L_Y` per agent-step.
* `fastmath=True` (FMA contraction, reassociation), `error_model='numpy'`,
  and 512-bit vectors on AVX-512 machines (LLVM prefers 256 bits there
  unless told otherwise: `NUMBA_CPU_FEATURES`, set below when unset).

Per agent-step: one sin/cos pair and two atan2 (own polynomials, vectorised),
three angle-sum turns, no libm call. The plain version (libm, one agent at a
time) is numba_star_plain.py.
"""

from __future__ import annotations

import math
import os

import numba
import numpy as np
from numba import njit, prange


def _prefer_512_bit_vectors() -> None:
    """On AVX-512 CPUs LLVM's cost model prefers 256-bit vectors; the agent loop
    runs ≈ 1.4x faster in 512-bit ones. Must run before Numba compiles anything
    (the target machine is made at the first compilation); respects a
    `NUMBA_CPU_FEATURES` the user set."""
    if os.environ.get("NUMBA_CPU_FEATURES") or numba.config.CPU_FEATURES is not None:
        return
    import llvmlite.binding as llvm  # noqa: PLC0415

    features = llvm.get_host_cpu_features().flatten()
    if "+avx512f" in features.split(","):
        numba.config.CPU_FEATURES = features + ",-prefer-256-bit"


_prefer_512_bit_vectors()

from formation import ETA, INERTIA, KE, KZ, MASS, PSI, V_D, W_D, L, formation, reference_table, star_class  # noqa: E402,F401

# Agents per tile (tiles of 64-256 ran alike; 32 slower).
TILE = 128

JIT = dict(fastmath=True, error_model="numpy", boundscheck=False, cache=True)
INLINE = dict(JIT, inline="always")

# Eq. 3 with 1/m and 1/J folded in.
A_W = PSI / INERTIA
B_V = ETA / MASS

# sin/cos: x = nπ/2 + y, π/2 in three parts (Cody-Waite), Cephes sin.c.
FRAC_2_PI = 2.0 / math.pi
PIO2_1 = 1.57079625129699707031e00
PIO2_2 = 7.54978941586159635336e-08
PIO2_3 = 5.3903028581581190529e-15
S0, S1, S2, S3, S4, S5 = (1.58962301576546568060e-10, -2.50507477628578072866e-8, 2.75573136213857245213e-6,
                          -1.98412698295895385996e-4, 8.33333333332211858878e-3, -1.66666666666666307295e-1)
C0, C1, C2, C3, C4, C5 = (-1.13585365213876817300e-11, 2.08757008419747316778e-9, -2.75573141792967388112e-7,
                          2.48015872888517045348e-5, -1.38888888888730564116e-3, 4.16666666666665929218e-2)
# atan: Cephes atan.c.
P0, P1, P2, P3, P4 = (-8.750608600031904122785e-1, -1.615753718733365076637e1, -7.500855792314704667340e1,
                      -1.228866684490136173410e2, -6.485021904942025371773e1)
Q1, Q2, Q3, Q4, Q5 = (2.485846490142306297962e1, 1.650270098316988542046e2, 4.328810604912902668951e2,
                      4.853903996359136964868e2, 1.945506571482613964425e2)
T3P8 = 2.41421356237309504880  # tan 3π/8
PIO2_LO = 6.123233995736765886130e-17  # π/2 − fl(π/2)
# A stage turn at most this large takes the angle-sum formulas.
TURN_LIMIT = 0.05

@njit(**INLINE)
def sin_cos(x):
    """`(sin x, cos x)`, branch-free (selects only), within 1 ulp of libm for
    the headings of this benchmark."""
    n = math.floor(x * FRAC_2_PI + 0.5)
    y = ((x - n * PIO2_1) - n * PIO2_2) - n * PIO2_3
    z = y * y
    s = y + y * z * (((((S0 * z + S1) * z + S2) * z + S3) * z + S4) * z + S5)
    c = (1.0 - 0.5 * z) + z * z * (((((C0 * z + C1) * z + C2) * z + C3) * z + C4) * z + C5)
    q = np.int64(n)
    swap = (q & 1) != 0
    ss = c if swap else s
    cc = s if swap else c
    ss = -ss if (q & 2) != 0 else ss
    cc = -cc if ((q + 1) & 2) != 0 else cc
    return ss, cc


@njit(**INLINE)
def turned(s, c, d):
    """`(sin(θ + d), cos(θ + d))` from `s = sin θ`, `c = cos θ`, for `|d| < 0.05`."""
    z = d * d
    sd = d + d * z * ((-1.0 / 5040.0 * z + 1.0 / 120.0) * z - 1.0 / 6.0)
    cm1 = z * (((1.0 / 40320.0 * z - 1.0 / 720.0) * z + 1.0 / 24.0) * z - 0.5)
    return s + (s * cm1 + c * sd), c + (c * cm1 - s * sd)


@njit(**INLINE)
def atan2(y, x):
    """`atan2(y, x)`, branch-free: `|y|/|x|` reduced to [0, 0.66] without
    forming the ratio first, Cephes' rational approximation, the quadrant."""
    ay, ax = abs(y), abs(x)
    big = ay > ax * T3P8
    mid = (not big) and ay > ax * 0.66
    num = -ax if big else (ay - ax if mid else ay)
    den = ay if big else (ay + ax if mid else ax)
    base = 0.5 * math.pi if big else (0.25 * math.pi if mid else 0.0)
    more = PIO2_LO if big else (0.5 * PIO2_LO if mid else 0.0)
    r = 0.0 if den == 0.0 else num / den
    z = r * r
    p = r * (z * ((((P0 * z + P1) * z + P2) * z + P3) * z + P4)
             / (((((z + Q1) * z + Q2) * z + Q3) * z + Q4) * z + Q5)) + r
    a = base + (p + more)
    a = ((math.pi - a) + 2.0 * PIO2_LO) if math.copysign(1.0, x) < 0.0 else a
    return math.copysign(a, y)


@njit(**INLINE)
def ly_comp(rc, inv_delta, k2, g2):
    """Eq. 6, `L_Ycomp`, as one angle: `2G · atan2(2ak², (1 + a²)² + k²(1 − a²))`,
    `a = R_C/δ` (capped at ±1e50, where the value is below 1e-100), `k = ε/δ`.
    `R_C = 0` on a straight line gives 0, as eq. 6 does there."""
    a = min(max(rc * inv_delta, -1e50), 1e50)
    a2 = a * a
    s = 1.0 + a2
    return g2 * atan2(2.0 * a * k2, s * s + k2 * (1.0 - a2))


@njit(**INLINE)
def rc_at(ref, n, k):
    """`R_C = V_d / ω_d` at instant `k` of step `n` (0 where `ω_d = 0`)."""
    return 0.0 if ref[n, k, 7] == 0.0 else ref[n, k, 6] / ref[n, k, 7]


@njit(**INLINE)
def accel(ax, ay, s, c, v, w, dpx, dpy, ddpx, ddpy, lx, ilx, ly):
    """`(v̇, ω̇)`: eqs. 7-13 (paper variant, `L̇_Y = L̈_Y = 0`) and eq. 3, with
    `(ax, ay)` the position minus the reference's and `s, c` = sin θ, cos θ."""
    e0 = c * ax + s * ay + lx
    e1 = c * ay - s * ax + ly
    rdp0 = c * dpx + s * dpy
    rdp1 = c * dpy - s * dpx
    rdd0 = c * ddpx + s * ddpy
    rdd1 = c * ddpy - s * ddpx
    z0 = v - w * ly - rdp0 + KE * e0
    z1 = w * lx - rdp1 + KE * e1
    de0 = w * e1 + z0 - KE * e0
    de1 = z1 - KE * e1 - w * e0
    h0 = ly * A_W * w - v * B_V - w * rdp1 + KE * de0
    h1 = w * rdp0 - lx * A_W * w + KE * de1
    w0 = rdd0 - h0 - KZ * z0
    w1 = rdd1 - h1 - KZ * z1
    # u = (m (w0 + w1 L_Y/L_X), J w1/L_X); v̇ = (u1 − ηv)/m, ω̇ = (u2 − ψω)/J.
    q = w1 * ilx
    return w0 + q * ly - B_V * v, q - A_W * w


@njit(**INLINE)
def rk4(x, y, th, v, w, lx, ilx, ly0, ly1, ly2,
        a0, a1, a2, a3, a4, a5, b0, b1, b2, b3, b4, b5, c0, c1, c2, c3, c4, c5, dt, turn):
    """One RK4 step of one agent: the reference `a` at `t_n`, `b` at `t_n + dt/2`,
    `c` at `t_{n+1}` (position, velocity, acceleration), `L_Y` there `ly0..2`.
    With `turn`, stages 2-4 turn stage 1's sin/cos; also returns whether some
    stage turned by `TURN_LIMIT` or more (then the caller redoes the step
    without `turn`)."""
    h = 0.5 * dt
    s1, k1 = sin_cos(th)
    dv1, dw1 = accel(x - a0, y - a1, s1, k1, v, w, a2, a3, a4, a5, lx, ilx, ly0)
    d2 = h * w
    v2 = v + h * dv1
    w2 = w + h * dw1
    s2, k2 = turned(s1, k1, d2) if turn else sin_cos(th + d2)
    dv2, dw2 = accel(x + h * (v * k1) - b0, y + h * (v * s1) - b1, s2, k2, v2, w2, b2, b3, b4, b5, lx, ilx, ly1)
    d3 = h * w2
    v3 = v + h * dv2
    w3 = w + h * dw2
    s3, k3 = turned(s1, k1, d3) if turn else sin_cos(th + d3)
    dv3, dw3 = accel(x + h * (v2 * k2) - b0, y + h * (v2 * s2) - b1, s3, k3, v3, w3, b2, b3, b4, b5, lx, ilx, ly1)
    d4 = dt * w3
    v4 = v + dt * dv3
    w4 = w + dt * dw3
    s4, k4 = turned(s1, k1, d4) if turn else sin_cos(th + d4)
    dv4, dw4 = accel(x + dt * (v3 * k3) - c0, y + dt * (v3 * s3) - c1, s4, k4, v4, w4, c2, c3, c4, c5, lx, ilx, ly2)
    h6 = dt / 6.0
    big = max(abs(d2), abs(d3), abs(d4)) >= TURN_LIMIT
    return (x + h6 * (v * k1 + 2.0 * (v2 * k2 + v3 * k3) + v4 * k4),
            y + h6 * (v * s1 + 2.0 * (v2 * s2 + v3 * s3) + v4 * s4),
            th + h6 * (w + 2.0 * (w2 + w3) + w4),
            v + h6 * (dv1 + 2.0 * (dv2 + dv3) + dv4),
            w + h6 * (dw1 + 2.0 * (dw2 + dw3) + dw4),
            big)


# Rows of a tile: the state (x, y, θ, v, ω, L_Y at t_n), the same before the
# step (for a redo), the constants (L_X, 1/L_X, L_Yoff, 2G, 1/δ, (ε/δ)²).
X, Y, TH, V, W, LY = 0, 1, 2, 3, 4, 5
OLD = 6
LX, ILX, LYOFF, G2, IDELTA, K2 = 12, 13, 14, 15, 16, 17
ROWS = 18


@njit(parallel=True, **JIT)
def run(x, y, th, v, w, lx, ly_off, g2, delta, eps, ref, dt):
    """`ref.shape[0]` RK4 steps of every agent, in place."""
    steps = ref.shape[0]
    agents = x.shape[0]
    tiles = (agents + TILE - 1) // TILE
    for t in prange(tiles):
        lo = t * TILE
        m = min(TILE, agents - lo)
        # One array with a constant row length: LLVM sees that the rows do not
        # overlap and vectorises without run-time alias checks.
        b = np.empty((ROWS, TILE))
        for i in range(TILE):
            j = lo + min(i, m - 1)  # the last tile is padded with its last agent
            b[X, i] = x[j]
            b[Y, i] = y[j]
            b[TH, i] = th[j]
            b[V, i] = v[j]
            b[W, i] = w[j]
            b[LX, i] = lx[j]
            b[ILX, i] = 1.0 / lx[j]
            b[LYOFF, i] = ly_off[j]
            b[G2, i] = g2[j]
            b[IDELTA, i] = 1.0 / delta[j]
            k = eps[j] / delta[j]
            b[K2, i] = k * k
        if steps > 0:
            rc0 = rc_at(ref, 0, 0)
            for i in range(TILE):
                b[LY, i] = b[LYOFF, i] + ly_comp(rc0, b[IDELTA, i], b[K2, i], b[G2, i])
        for n in range(steps):
            rc1, rc2 = rc_at(ref, n, 1), rc_at(ref, n, 2)
            a0, a1, a2, a3, a4, a5 = ref[n, 0, 0], ref[n, 0, 1], ref[n, 0, 2], ref[n, 0, 3], ref[n, 0, 4], ref[n, 0, 5]
            b0, b1, b2, b3, b4, b5 = ref[n, 1, 0], ref[n, 1, 1], ref[n, 1, 2], ref[n, 1, 3], ref[n, 1, 4], ref[n, 1, 5]
            c0, c1, c2, c3, c4, c5 = ref[n, 2, 0], ref[n, 2, 1], ref[n, 2, 2], ref[n, 2, 3], ref[n, 2, 4], ref[n, 2, 5]
            big = 0
            for i in range(TILE):
                xi, yi, ti, vi, wi, ly0 = b[X, i], b[Y, i], b[TH, i], b[V, i], b[W, i], b[LY, i]
                b[OLD + X, i] = xi
                b[OLD + Y, i] = yi
                b[OLD + TH, i] = ti
                b[OLD + V, i] = vi
                b[OLD + W, i] = wi
                b[OLD + LY, i] = ly0
                ly1 = b[LYOFF, i] + ly_comp(rc1, b[IDELTA, i], b[K2, i], b[G2, i])
                ly2 = b[LYOFF, i] + ly_comp(rc2, b[IDELTA, i], b[K2, i], b[G2, i])
                xn, yn, tn, vn, wn, bad = rk4(xi, yi, ti, vi, wi, b[LX, i], b[ILX, i], ly0, ly1, ly2,
                                              a0, a1, a2, a3, a4, a5, b0, b1, b2, b3, b4, b5,
                                              c0, c1, c2, c3, c4, c5, dt, True)
                b[X, i] = xn
                b[Y, i] = yn
                b[TH, i] = tn
                b[V, i] = vn
                b[W, i] = wn
                b[LY, i] = ly2
                big += bad
            if big > 0:
                # Some stage turned by 0.05 rad or more: the step again, with
                # sin/cos in every stage.
                for i in range(TILE):
                    ly1 = b[LYOFF, i] + ly_comp(rc1, b[IDELTA, i], b[K2, i], b[G2, i])
                    xn, yn, tn, vn, wn, bad = rk4(b[OLD + X, i], b[OLD + Y, i], b[OLD + TH, i], b[OLD + V, i],
                                                  b[OLD + W, i], b[LX, i], b[ILX, i], b[OLD + LY, i], ly1, b[LY, i],
                                                  a0, a1, a2, a3, a4, a5, b0, b1, b2, b3, b4, b5,
                                                  c0, c1, c2, c3, c4, c5, dt, False)
                    b[X, i] = xn
                    b[Y, i] = yn
                    b[TH, i] = tn
                    b[V, i] = vn
                    b[W, i] = wn
        for i in range(m):
            x[lo + i] = b[X, i]
            y[lo + i] = b[Y, i]
            th[lo + i] = b[TH, i]
            v[lo + i] = b[V, i]
            w[lo + i] = b[W, i]


@njit(**JIT)
def errors(x, y, th, lx, ly_off, g2, delta, eps, r):
    """Every agent's `‖e‖` (eq. 7) against the reference row `r`."""
    out = np.empty(x.shape[0])
    rc = 0.0 if r[7] == 0.0 else r[6] / r[7]
    for i in range(x.shape[0]):
        k = eps[i] / delta[i]
        ly = ly_off[i] + ly_comp(rc, 1.0 / delta[i], k * k, g2[i])
        s, c = math.sin(th[i]), math.cos(th[i])
        ax, ay = x[i] - r[0], y[i] - r[1]
        e0 = c * ax + s * ay + lx[i]
        e1 = -s * ax + c * ay + ly
        out[i] = math.sqrt(e0 * e0 + e1 * e1)
    return out


Star = star_class(run, reference_table, errors)
