//! The same problems solved by clarabel (interior point, default tolerances
//! 1e-8): the fallback beyond [`MAX_ROWS`] rows and the tests' reference.
//! It builds its solver (and so allocates) on every call.

use super::*;
use clarabel::algebra::CscMatrix;
use clarabel::solver::{DefaultSettings, DefaultSolver, IPSolver, NonnegativeConeT, SolverStatus};

/// [`super::solve_relaxed`] by clarabel, before its check of the hard rows.
pub(in crate::safety) fn solve_relaxed(
    rows: &[Constraint],
    soft_end: usize,
    want: [f64; 2],
) -> Option<[f64; 2]> {
    solve_relaxed_status(rows, soft_end, want).ok()
}

/// The same, or the status clarabel ended with.
pub(in crate::safety) fn solve_relaxed_status(
    rows: &[Constraint],
    soft_end: usize,
    want: [f64; 2],
) -> Result<[f64; 2], SolverStatus> {
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
    clarabel_solve(&p, &q, &a, &b)
}

/// [`super::solve`] by clarabel, before its check of the rows.
pub(in crate::safety) fn solve(rows: &[Constraint], want: [f64; 2]) -> Option<[f64; 2]> {
    solve_status(rows, want).ok()
}

/// The same, or the status clarabel ended with.
pub(in crate::safety) fn solve_status(
    rows: &[Constraint],
    want: [f64; 2],
) -> Result<[f64; 2], SolverStatus> {
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
    clarabel_solve(&p, &q, &a, &b)
}

/// `argmin ½zᵀPz + qᵀz` s.t. `A z ≤ b` by clarabel (default tolerances, quiet):
/// the first two components of `z`, else the status it ended with.
fn clarabel_solve(
    p: &CscMatrix<f64>,
    q: &[f64],
    a: &CscMatrix<f64>,
    b: &[f64],
) -> Result<[f64; 2], SolverStatus> {
    let settings = DefaultSettings {
        verbose: false,
        ..DefaultSettings::default()
    };
    let cones = [NonnegativeConeT(b.len())];
    let mut solver =
        DefaultSolver::new(p, q, a, b, &cones, settings).map_err(|_| SolverStatus::Unsolved)?;
    solver.solve();
    match solver.solution.status {
        SolverStatus::Solved | SolverStatus::AlmostSolved => {
            Ok([solver.solution.x[0], solver.solution.x[1]])
        }
        status => Err(status),
    }
}
