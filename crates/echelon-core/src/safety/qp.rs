//! The quadratic program: its rows ([`Constraint`]), their tolerance and
//! their exact solution by enumeration of active sets (exact, or with the
//! soft rows relaxed), with clarabel (the `clarabel` feature, which
//! `echelon` turns on) kept as the reference and as the fallback for
//! problems of more than [`MAX_ROWS`] rows. Without the feature the
//! enumeration answers every problem: exact, and without the heap, but its
//! cost grows as `m³` (`m⁴` relaxed) beyond [`MAX_ROWS`].
//!
//! ## The exact solver
//!
//! `argmin ½‖z − w‖²` s.t. `g_k · z ≥ h_k` is the projection of `w` onto a
//! convex polyhedron. At the optimum `z*` the KKT conditions read
//! `z* − w = Σ λ_k g_k`, `λ ≥ 0`, over the active rows, and (conic
//! Carathéodory) the active rows can be taken linearly independent, so at
//! most `n` of them in `n` dimensions: `z*` is the projection of `w` onto the
//! intersection of at most `n` of the rows' boundaries, with non-negative
//! multipliers. Every such projection (`w` itself, one row's, the vertex of
//! two, in three dimensions of three) is a candidate; a feasible candidate is
//! never closer to `w` than `z*` (which is feasible), so the closest feasible
//! candidate *is* `z*`. The enumeration costs `O(mⁿ⁺¹)` flops at worst (`m`
//! rows) and nothing on the heap: `n = 2` for the filter's QP in
//! `x = (x₁, x₂)`, `n = 3` for the relaxed one in `(x₁, x₂, √W s)`.
//!
//! Candidates are first accepted only if they break no row by more than
//! `1e-9 (1 + |h_k| + Σ|g_kc z_c|)` (rounding); if none is, the closest one
//! within the caller's tolerance ([`TOLERANCE`], as clarabel's answers were
//! held to) is taken, else the rows are infeasible (`None`).

/// How far (in the QP's units: m²/s for velocity bases, m²/s² for torques)
/// the solver's answer may break a constraint before it is refused.
pub const TOLERANCE: f64 = 1e-6;

/// Problems with more rows than this (barriers and limits; 24 neighbours in
/// range with a torque robot's eight limit rows) go to clarabel, which
/// allocates, instead of the enumeration, whose cost grows as `m³` (`m⁴`
/// relaxed): with the `clarabel` feature; without it the enumeration
/// answers them too.
pub const MAX_ROWS: usize = 32;

/// Whether the filter uses the exact enumeration (else clarabel). On: its
/// answers are exact where clarabel's interior point stops at its 1e-8
/// tolerances; the `crossing` and `obstacle-slalom` goldens were re-blessed
/// for it (their values moved by about 1e-7 relative, one saturated tick
/// in `crossing`), deliberately, when it was switched on.
const USE_EXACT: bool = true;

/// `W` of the relaxed QP: the weight of the shared slack.
const W: f64 = 1e6;

/// Rounding allowed to a candidate in the first pass, relative.
const ROUNDING: f64 = 1e-9;

/// One constraint given to the QP: `a · x ≥ b` in the QP's variables
/// (`x = (v, L ω)` or `x = (u1/m, L u2/J)`, see the module documentation).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Constraint {
    /// Row `a`.
    pub a: [f64; 2],
    /// Bound `b`.
    pub b: f64,
}

impl Constraint {
    /// How far `x` satisfies it: `a · x − b` (negative: broken).
    #[inline]
    pub fn slack(&self, x: [f64; 2]) -> f64 {
        self.a[0] * x[0] + self.a[1] * x[1] - self.b
    }
}

/// `argmin ½‖x − want‖² + ½ W s²` s.t. `a_k·x + s ≥ b_k` for the rows before
/// `soft_end` (one shared slack `s ≥ 0`, `W` = 10⁶) and `a_k·x ≥ b_k` for the
/// rest: the command that breaks the soft rows least, within the hard ones.
/// `None` when even the hard rows cannot be met.
pub(super) fn solve_relaxed(
    rows: &[Constraint],
    soft_end: usize,
    want: [f64; 2],
) -> Option<[f64; 2]> {
    relaxed_with(rows, soft_end, want, exact_for(rows.len()))
}

/// Whether a problem of `rows` rows goes to the enumeration: all do without
/// the `clarabel` feature.
#[inline]
fn exact_for(rows: usize) -> bool {
    !cfg!(feature = "clarabel") || (USE_EXACT && rows <= MAX_ROWS)
}

/// [`solve_relaxed`] by the enumeration (`exact`) or by clarabel.
fn relaxed_with(
    rows: &[Constraint],
    soft_end: usize,
    want: [f64; 2],
    exact: bool,
) -> Option<[f64; 2]> {
    let x = if exact {
        exact_relaxed(rows, soft_end, want, TOLERANCE)?
    } else {
        fallback::solve_relaxed(rows, soft_end, want)?
    };
    let hard_ok = rows[soft_end..]
        .iter()
        .all(|c| c.slack(x) >= -TOLERANCE * (1.0 + c.b.abs()));
    (x.iter().all(|v| v.is_finite()) && hard_ok).then_some(x)
}

/// `|x_k| ≤ bound_k` as four rows (an infinite bound adds none).
pub(super) fn push_box(rows: &mut Vec<Constraint>, bound: [f64; 2]) {
    push_band(rows, [0.0; 2], bound);
}

/// `|x_k − centre_k| ≤ bound_k` as four rows (an infinite bound adds none).
pub(super) fn push_band(rows: &mut Vec<Constraint>, centre: [f64; 2], bound: [f64; 2]) {
    for (k, b) in bound.into_iter().enumerate() {
        if b.is_finite() {
            let mut a = [0.0; 2];
            a[k] = 1.0;
            rows.push(Constraint {
                a,
                b: centre[k] - b,
            });
            a[k] = -1.0;
            rows.push(Constraint {
                a,
                b: -centre[k] - b,
            });
        }
    }
}

/// `argmin ½‖x − want‖²` s.t. every row; `None` when the rows are infeasible
/// (or the answer breaks a row by more than [`TOLERANCE`]).
pub(super) fn solve(rows: &[Constraint], want: [f64; 2]) -> Option<[f64; 2]> {
    solve_split(rows, &[], want)
}

/// [`solve`] for the rows of `first` and then `second` (no copy).
pub(super) fn solve_split(
    first: &[Constraint],
    second: &[Constraint],
    want: [f64; 2],
) -> Option<[f64; 2]> {
    split_with(first, second, want, exact_for(first.len() + second.len()))
}

/// [`solve_split`] by the enumeration (`exact`) or by clarabel.
fn split_with(
    first: &[Constraint],
    second: &[Constraint],
    want: [f64; 2],
    exact: bool,
) -> Option<[f64; 2]> {
    let x = if exact {
        self::exact(first, second, want, TOLERANCE)?
    } else {
        let rows: Vec<Constraint> = first.iter().chain(second).copied().collect();
        fallback::solve(&rows, want)?
    };
    let ok = |c: &Constraint| c.slack(x) >= -TOLERANCE;
    (x.iter().all(|v| v.is_finite()) && first.iter().all(ok) && second.iter().all(ok)).then_some(x)
}

#[inline]
fn dot<const N: usize>(a: [f64; N], b: [f64; N]) -> f64 {
    let mut s = 0.0;
    for k in 0..N {
        s += a[k] * b[k];
    }
    s
}

/// `Σ |a_k b_k|`, the scale of `a · b`'s rounding.
#[inline]
fn abs_dot<const N: usize>(a: [f64; N], b: [f64; N]) -> f64 {
    let mut s = 0.0;
    for k in 0..N {
        s += (a[k] * b[k]).abs();
    }
    s
}

#[inline]
fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

/// The rows `g_k · z ≥ h_k` of a projection problem in `N` dimensions.
trait Rows<const N: usize> {
    fn len(&self) -> usize;
    fn row(&self, k: usize) -> ([f64; N], f64);
}

/// The filter's QP in `x`: the rows of two slices.
struct Split<'a>(&'a [Constraint], &'a [Constraint]);

impl Rows<2> for Split<'_> {
    #[inline]
    fn len(&self) -> usize {
        self.0.len() + self.1.len()
    }
    #[inline]
    fn row(&self, k: usize) -> ([f64; 2], f64) {
        let c = if k < self.0.len() {
            self.0[k]
        } else {
            self.1[k - self.0.len()]
        };
        (c.a, c.b)
    }
}

/// The relaxed QP in `z = (x₁, x₂, √W s)`: soft rows `a·x + z₃/√W ≥ b`,
/// hard rows `a·x ≥ b`, and `z₃ ≥ 0` (the last row).
struct Relaxed<'a> {
    rows: &'a [Constraint],
    soft_end: usize,
}

impl Rows<3> for Relaxed<'_> {
    #[inline]
    fn len(&self) -> usize {
        self.rows.len() + 1
    }
    #[inline]
    fn row(&self, k: usize) -> ([f64; 3], f64) {
        match self.rows.get(k) {
            Some(c) => {
                let t = if k < self.soft_end {
                    1.0 / W.sqrt()
                } else {
                    0.0
                };
                ([c.a[0], c.a[1], t], c.b)
            }
            None => ([0.0, 0.0, 1.0], 0.0),
        }
    }
}

/// How far a candidate may break a row `g · z ≥ h`.
#[derive(Debug, Clone, Copy)]
enum Allowed {
    /// Rounding: [`ROUNDING`] `(1 + |h| + Σ|g_c z_c|)`.
    Rounding,
    /// A fixed amount.
    Absolute(f64),
    /// `tol (1 + |h|)`.
    Bound(f64),
}

impl Allowed {
    #[inline]
    fn of<const N: usize>(self, g: [f64; N], h: f64, z: [f64; N]) -> f64 {
        match self {
            Allowed::Rounding => ROUNDING * (1.0 + h.abs() + abs_dot(g, z)),
            Allowed::Absolute(tol) => tol,
            Allowed::Bound(tol) => tol * (1.0 + h.abs()),
        }
    }
}

/// Whether `z` satisfies every row within `allowed`.
#[inline]
fn feasible<const N: usize>(rows: &impl Rows<N>, z: [f64; N], allowed: Allowed) -> bool {
    (0..rows.len()).all(|k| {
        let (g, h) = rows.row(k);
        dot(g, z) - h >= -allowed.of(g, h, z)
    })
}

/// Whether the multipliers `λ_k` (of rows `g_k`) may be those of the optimum:
/// none below zero beyond rounding.
#[inline]
fn multipliers_ok<const N: usize>(lambda: &[f64], g: &[[f64; N]]) -> bool {
    let size: f64 = lambda
        .iter()
        .zip(g)
        .map(|(l, g)| l.abs() * dot(*g, *g).sqrt())
        .sum();
    lambda
        .iter()
        .zip(g)
        .all(|(l, g)| l * dot(*g, *g).sqrt() >= -ROUNDING * (1.0 + size))
}

/// The closest candidate to `w` that breaks no row beyond the tolerance of
/// the pass (see the module documentation).
struct Best<const N: usize> {
    z: Option<[f64; N]>,
    d2: f64,
}

impl<const N: usize> Best<N> {
    fn new() -> Best<N> {
        Best {
            z: None,
            d2: f64::INFINITY,
        }
    }

    #[inline]
    fn offer(&mut self, rows: &impl Rows<N>, w: [f64; N], z: [f64; N], allowed: Allowed) {
        let mut d2 = 0.0;
        for k in 0..N {
            d2 += (z[k] - w[k]) * (z[k] - w[k]);
        }
        if d2 < self.d2 && z.iter().all(|v| v.is_finite()) && feasible(rows, z, allowed) {
            self.z = Some(z);
            self.d2 = d2;
        }
    }
}

/// Two rows are parallel (no vertex) when the sine of their angle is below
/// this.
const PARALLEL: f64 = 1e-12;

/// The projection of `w` onto the rows `g · z ≥ h` (within `allowed`) by
/// enumeration: `w` itself when it meets them, else the closest of its
/// projections onto each single row it breaks and of the candidates that
/// `vertices` offers (onto the intersections of two rows and more, which
/// depend on the dimension).
fn project<const N: usize, R: Rows<N>>(
    rows: &R,
    w: [f64; N],
    allowed: Allowed,
    vertices: fn(&R, [f64; N], Allowed, &mut Best<N>),
) -> Option<[f64; N]> {
    let mut best = Best::new();
    best.offer(rows, w, w, allowed);
    if best.z.is_some() {
        return best.z;
    }
    for i in 0..rows.len() {
        let (g, h) = rows.row(i);
        let gg = dot(g, g);
        let r = h - dot(g, w);
        // λ = r/‖g‖² ≥ 0: only a row that w breaks.
        if gg > 0.0 && r > 0.0 {
            let l = r / gg;
            best.offer(rows, w, std::array::from_fn(|k| w[k] + l * g[k]), allowed);
        }
    }
    vertices(rows, w, allowed, &mut best);
    best.z
}

/// [`project`]'s candidates in the plane: the vertices of two rows.
fn vertices2<R: Rows<2>>(rows: &R, w: [f64; 2], allowed: Allowed, best: &mut Best<2>) {
    let m = rows.len();
    for i in 0..m {
        let (gi, hi) = rows.row(i);
        let ni = dot(gi, gi).sqrt();
        if ni == 0.0 {
            continue;
        }
        for j in i + 1..m {
            let (gj, hj) = rows.row(j);
            let det = gi[0] * gj[1] - gi[1] * gj[0];
            if det.abs() <= PARALLEL * ni * dot(gj, gj).sqrt() {
                continue;
            }
            // The vertex z = w + d: [gi; gj] d = (ri, rj).
            let (ri, rj) = (hi - dot(gi, w), hj - dot(gj, w));
            let d = [
                (ri * gj[1] - rj * gi[1]) / det,
                (gi[0] * rj - gj[0] * ri) / det,
            ];
            let z = [w[0] + d[0], w[1] + d[1]];
            let d2 = dot(d, d);
            if d2 >= best.d2 {
                continue;
            }
            // z − w = λi gi + λj gj.
            let li = (d[0] * gj[1] - d[1] * gj[0]) / det;
            let lj = (gi[0] * d[1] - gi[1] * d[0]) / det;
            if multipliers_ok(&[li, lj], &[gi, gj]) {
                best.offer(rows, w, z, allowed);
            }
        }
    }
}

/// [`project`]'s candidates in space: the projections onto the line of two
/// rows and the vertices of three.
fn vertices3<R: Rows<3>>(rows: &R, w: [f64; 3], allowed: Allowed, best: &mut Best<3>) {
    let m = rows.len();
    for i in 0..m {
        let (gi, hi) = rows.row(i);
        let gii = dot(gi, gi);
        let ri = hi - dot(gi, w);
        for j in i + 1..m {
            let (gj, hj) = rows.row(j);
            let gjj = dot(gj, gj);
            let c = cross(gi, gj);
            let det = dot(c, c);
            if det.sqrt() <= PARALLEL * (gii * gjj).sqrt() {
                continue;
            }
            // The projection onto the line z = w + d: gi·d = ri, gj·d = rj,
            // c·d = 0 (d in the span of gi, gj); d = Σ λ g.
            let rj = hj - dot(gj, w);
            let (gjc, cgi) = (cross(gj, c), cross(c, gi));
            let mut d = [0.0; 3];
            for k in 0..3 {
                d[k] = (ri * gjc[k] + rj * cgi[k]) / det;
            }
            if dot(d, d) >= best.d2 {
                continue;
            }
            // λ from d = λi gi + λj gj: λi = (gj × c)·d/‖c‖² (gi·(gj×c) = ‖c‖²).
            let li = dot(gjc, d) / det;
            let lj = dot(cgi, d) / det;
            if !multipliers_ok(&[li, lj], &[gi, gj]) {
                continue;
            }
            best.offer(rows, w, [w[0] + d[0], w[1] + d[1], w[2] + d[2]], allowed);
        }
    }
    for i in 0..m {
        let (gi, hi) = rows.row(i);
        for j in i + 1..m {
            let (gj, hj) = rows.row(j);
            let cij = cross(gi, gj);
            for l in j + 1..m {
                let (gl, hl) = rows.row(l);
                let det = dot(gl, cij);
                let scale = dot(gi, gi).sqrt() * dot(gj, gj).sqrt() * dot(gl, gl).sqrt();
                if det.abs() <= PARALLEL * scale {
                    continue;
                }
                // The vertex z = w + d: d = (ri (gj×gl) + rj (gl×gi) + rl (gi×gj)) / det.
                let cjl = cross(gj, gl);
                let cli = cross(gl, gi);
                let (ri, rj, rl) = (hi - dot(gi, w), hj - dot(gj, w), hl - dot(gl, w));
                let mut d = [0.0; 3];
                for k in 0..3 {
                    d[k] = (ri * cjl[k] + rj * cli[k] + rl * cij[k]) / det;
                }
                let z = [w[0] + d[0], w[1] + d[1], w[2] + d[2]];
                if dot(d, d) >= best.d2 {
                    continue;
                }
                // z − w = Mᵀλ: λ = M⁻ᵀ (z − w), M⁻¹'s columns the cross products.
                let lambda = [dot(cjl, d) / det, dot(cli, d) / det, dot(cij, d) / det];
                if multipliers_ok(&lambda, &[gi, gj, gl]) {
                    best.offer(rows, w, z, allowed);
                }
            }
        }
    }
}

/// The exact answer of [`solve_split`] by enumeration, its second pass
/// allowed to break rows by `tol` (absolute, as [`solve`]'s check).
fn exact(
    first: &[Constraint],
    second: &[Constraint],
    want: [f64; 2],
    tol: f64,
) -> Option<[f64; 2]> {
    let rows = Split(first, second);
    project(&rows, want, Allowed::Rounding, vertices2)
        .or_else(|| project(&rows, want, Allowed::Absolute(tol), vertices2))
}

/// The exact answer of [`solve_relaxed`] by enumeration in `(x, √W s)`.
fn exact_relaxed(
    rows: &[Constraint],
    soft_end: usize,
    want: [f64; 2],
    tol: f64,
) -> Option<[f64; 2]> {
    let problem = Relaxed { rows, soft_end };
    let w = [want[0], want[1], 0.0];
    project(&problem, w, Allowed::Rounding, vertices3)
        .or_else(|| project(&problem, w, Allowed::Bound(tol), vertices3))
        .map(|z| [z[0], z[1]])
}

/// The same problems solved by clarabel (interior point, default tolerances
/// 1e-8): the fallback beyond [`MAX_ROWS`] rows and the tests' reference.
/// It builds its solver (and so allocates) on every call.
#[cfg(feature = "clarabel")]
pub(super) mod reference;

/// Beyond [`MAX_ROWS`]: clarabel with the `clarabel` feature, else the
/// enumeration (never reached: [`exact_for`] sends every problem to it).
mod fallback {
    #[cfg(feature = "clarabel")]
    pub(super) use super::reference::{solve, solve_relaxed};

    #[cfg(not(feature = "clarabel"))]
    pub(super) fn solve(rows: &[super::Constraint], want: [f64; 2]) -> Option<[f64; 2]> {
        super::exact(rows, &[], want, super::TOLERANCE)
    }

    #[cfg(not(feature = "clarabel"))]
    pub(super) fn solve_relaxed(
        rows: &[super::Constraint],
        soft_end: usize,
        want: [f64; 2],
    ) -> Option<[f64; 2]> {
        super::exact_relaxed(rows, soft_end, want, super::TOLERANCE)
    }
}

// The solver's tests hold the enumeration to clarabel's answers.
#[cfg(all(test, feature = "clarabel"))]
mod tests;
