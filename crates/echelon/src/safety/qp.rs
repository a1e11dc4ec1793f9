//! The quadratic program: its rows ([`Constraint`]), their tolerance and
//! their solution by clarabel (exact, or with the soft rows relaxed).

use clarabel::algebra::CscMatrix;
use clarabel::solver::{DefaultSettings, DefaultSolver, IPSolver, NonnegativeConeT, SolverStatus};

/// How far (in the QP's units: m²/s for velocity bases, m²/s² for torques)
/// the solver's answer may break a constraint before it is refused.
pub const TOLERANCE: f64 = 1e-6;

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
/// `None` when even the hard rows cannot be met or the solver fails.
pub(super) fn solve_relaxed(
    rows: &[Constraint],
    soft_end: usize,
    want: [f64; 2],
) -> Option<[f64; 2]> {
    const W: f64 = 1e6;
    let m = rows.len() + 1;
    let p = CscMatrix::new(3, 3, vec![0, 1, 2, 3], vec![0, 1, 2], vec![1.0, 1.0, W]);
    let q = [-want[0], -want[1], 0.0];
    // Columns x₁, x₂, s; rows: −a·x − s ≤ −b (soft), −a·x ≤ −b (hard), −s ≤ 0.
    let mut colptr = vec![0, rows.len(), 2 * rows.len()];
    let mut rowval: Vec<usize> = (0..rows.len()).chain(0..rows.len()).collect();
    let mut nz: Vec<f64> = rows.iter().map(|c| -c.a[0]).collect();
    nz.extend(rows.iter().map(|c| -c.a[1]));
    rowval.extend(0..soft_end);
    nz.extend(std::iter::repeat_n(-1.0, soft_end));
    rowval.push(rows.len());
    nz.push(-1.0);
    colptr.push(nz.len());
    let a = CscMatrix::new(m, 3, colptr, rowval, nz);
    let mut b: Vec<f64> = rows.iter().map(|c| -c.b).collect();
    b.push(0.0);
    let x = clarabel_solve(&p, &q, &a, &b)?;
    let hard_ok = rows[soft_end..]
        .iter()
        .all(|c| c.slack(x) >= -TOLERANCE * (1.0 + c.b.abs()));
    (x.iter().all(|v| v.is_finite()) && hard_ok).then_some(x)
}

/// `|x_k| ≤ bound_k` as four rows (an infinite bound adds none).
pub(super) fn push_box(rows: &mut Vec<Constraint>, bound: [f64; 2]) {
    for (k, b) in bound.into_iter().enumerate() {
        if b.is_finite() {
            let mut a = [0.0; 2];
            a[k] = 1.0;
            rows.push(Constraint { a, b: -b });
            a[k] = -1.0;
            rows.push(Constraint { a, b: -b });
        }
    }
}

/// `argmin ½‖x − want‖²` s.t. every row, by clarabel; `None` when it finds no
/// solution or its answer breaks a row by more than [`TOLERANCE`].
///
/// clarabel builds its solver (and so allocates) on every call; the filter
/// calls it only when the nominal command breaks a constraint.
pub(super) fn solve(rows: &[Constraint], want: [f64; 2]) -> Option<[f64; 2]> {
    let m = rows.len();
    let p = CscMatrix::new(2, 2, vec![0, 1, 2], vec![0, 1], vec![1.0, 1.0]);
    let q = [-want[0], -want[1]];
    // clarabel's form: A x + s = b, s ≥ 0, i.e. −a·x ≤ −b.
    let mut nz = Vec::with_capacity(2 * m);
    nz.extend(rows.iter().map(|c| -c.a[0]));
    nz.extend(rows.iter().map(|c| -c.a[1]));
    let rowval: Vec<usize> = (0..m).chain(0..m).collect();
    let a = CscMatrix::new(m, 2, vec![0, m, 2 * m], rowval, nz);
    let b: Vec<f64> = rows.iter().map(|c| -c.b).collect();
    let x = clarabel_solve(&p, &q, &a, &b)?;
    (x.iter().all(|v| v.is_finite()) && rows.iter().all(|c| c.slack(x) >= -TOLERANCE)).then_some(x)
}

/// `argmin ½zᵀPz + qᵀz` s.t. `A z ≤ b` by clarabel (default tolerances, quiet):
/// the first two components of `z`, `None` unless solved.
fn clarabel_solve(
    p: &CscMatrix<f64>,
    q: &[f64],
    a: &CscMatrix<f64>,
    b: &[f64],
) -> Option<[f64; 2]> {
    let settings = DefaultSettings {
        verbose: false,
        ..DefaultSettings::default()
    };
    let cones = [NonnegativeConeT(b.len())];
    let mut solver = DefaultSolver::new(p, q, a, b, &cones, settings).ok()?;
    solver.solve();
    match solver.solution.status {
        SolverStatus::Solved | SolverStatus::AlmostSolved => {
            Some([solver.solution.x[0], solver.solution.x[1]])
        }
        _ => None,
    }
}
