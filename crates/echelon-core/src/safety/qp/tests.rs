#![allow(clippy::unwrap_used)]

use super::*;
use clarabel::solver::SolverStatus;
use proptest::prelude::*;

/// `½‖x − want‖²`.
fn objective(x: [f64; 2], want: [f64; 2]) -> f64 {
    0.5 * ((x[0] - want[0]).powi(2) + (x[1] - want[1]).powi(2))
}

/// `½‖x − want‖² + ½ W s²` with the least slack `s ≥ 0` the soft rows need.
fn relaxed_objective(rows: &[Constraint], soft_end: usize, x: [f64; 2], want: [f64; 2]) -> f64 {
    let s = rows[..soft_end]
        .iter()
        .map(|c| -c.slack(x))
        .fold(0.0f64, f64::max);
    objective(x, want) + 0.5 * W * s * s
}

/// What clarabel's answer became before the exact solver: the reference
/// with the same checks as [`solve`] and [`solve_relaxed`].
/// `Err(status)`: clarabel ended without a solution; `Ok(None)`: its
/// answer failed the check.
fn clarabel(rows: &[Constraint], want: [f64; 2]) -> Result<Option<[f64; 2]>, SolverStatus> {
    let x = reference::solve_status(rows, want)?;
    Ok(
        (x.iter().all(|v| v.is_finite()) && rows.iter().all(|c| c.slack(x) >= -TOLERANCE))
            .then_some(x),
    )
}

fn clarabel_relaxed(
    rows: &[Constraint],
    soft_end: usize,
    want: [f64; 2],
) -> Result<Option<[f64; 2]>, SolverStatus> {
    let x = reference::solve_relaxed_status(rows, soft_end, want)?;
    let hard_ok = rows[soft_end..]
        .iter()
        .all(|c| c.slack(x) >= -TOLERANCE * (1.0 + c.b.abs()));
    Ok((x.iter().all(|v| v.is_finite()) && hard_ok).then_some(x))
}

/// One row: a random one, or one parallel to (same or opposite
/// direction), nearly parallel to, or a copy of an earlier row, or a
/// zero row.
#[derive(Debug, Clone)]
enum Kind {
    Random { angle: f64, norm: f64 },
    Parallel { of: usize, scale: f64 },
    NearlyParallel { of: usize, turn: f64 },
    Copy { of: usize },
    Zero,
}

fn kind() -> impl Strategy<Value = Kind> {
    prop_oneof![
        6 => (-3.2..3.2f64, prop_oneof![0.05..2.0f64, 2.0..200.0f64])
            .prop_map(|(angle, norm)| Kind::Random { angle, norm }),
        2 => (any::<usize>(), prop_oneof![-3.0..-0.1f64, 0.1..3.0f64])
            .prop_map(|(of, scale)| Kind::Parallel { of, scale }),
        2 => (any::<usize>(), prop_oneof![-1e-3..1e-3f64, -1e-7..1e-7f64])
            .prop_map(|(of, turn)| Kind::NearlyParallel { of, turn }),
        1 => any::<usize>().prop_map(|of| Kind::Copy { of }),
        1 => Just(Kind::Zero),
    ]
}

/// 1–12 rows (`a`, `b`); `b = a · c − offset ‖a‖` around a random
/// centre `c` (offset in ±spread: the set is feasible while every offset
/// is positive, and may be either otherwise).
fn rows() -> impl Strategy<Value = Vec<Constraint>> {
    (
        prop::collection::vec((kind(), -1.0..1.0f64), 1..=12),
        (-1.5..1.5f64, -1.5..1.5f64),
        0.0..2.0f64,
        -0.5..1.0f64,
    )
        .prop_map(|(kinds, c, spread, bias)| {
            let mut rows: Vec<Constraint> = Vec::new();
            for (kind, offset) in kinds {
                let n = rows.len();
                let a = match kind {
                    Kind::Parallel { of, scale } if n > 0 => {
                        let a = rows[of % n].a;
                        [scale * a[0], scale * a[1]]
                    }
                    Kind::NearlyParallel { of, turn } if n > 0 => {
                        let a = rows[of % n].a;
                        let (sin, cos) = turn.sin_cos();
                        [cos * a[0] - sin * a[1], sin * a[0] + cos * a[1]]
                    }
                    Kind::Copy { of } if n > 0 => {
                        rows.push(rows[of % n]);
                        continue;
                    }
                    Kind::Zero => [0.0, 0.0],
                    Kind::Random { angle, norm } => [norm * angle.cos(), norm * angle.sin()],
                    _ => [1.0, 0.0],
                };
                let norm = a[0].hypot(a[1]);
                let b = a[0] * c.0 + a[1] * c.1 - (bias + offset * spread) * norm.max(0.5);
                rows.push(Constraint { a, b });
            }
            rows
        })
}

/// Whether the hard problem's answer is on a knife's edge: feasible
/// within a loose tolerance (1e-4) but not exactly, where clarabel and
/// the enumeration may each say either.
fn marginal(first: &[Constraint], want: [f64; 2]) -> bool {
    let rows = Split(first, &[]);
    project(&rows, want, Allowed::Rounding, vertices2).is_none()
        && project(&rows, want, Allowed::Absolute(1e-4), vertices2).is_some()
}

fn marginal_relaxed(rows: &[Constraint], soft_end: usize, want: [f64; 2]) -> bool {
    let hard = &rows[soft_end..];
    // The soft rows can always be met (s large): only the hard ones decide.
    marginal(hard, want)
}

/// Whether the `hard` rows meet nowhere within 10³ of `want` (nearly
/// parallel rows of opposite sense: seen, a pair meeting only 7.3e6 away):
/// no command a robot could take, so the enumeration's `None` (the filter
/// then brakes) is as good an answer as clarabel's far point. Shown by
/// both solvers finding nothing once the rows are boxed to 10³ around `want`.
fn meet_only_far(hard: &[Constraint], want: [f64; 2]) -> bool {
    let mut boxed = hard.to_vec();
    for (a, b) in [
        ([1.0, 0.0], want[0] - 1e3),
        ([-1.0, 0.0], -want[0] - 1e3),
        ([0.0, 1.0], want[1] - 1e3),
        ([0.0, -1.0], -want[1] - 1e3),
    ] {
        boxed.push(Constraint { a, b });
    }
    split_with(&boxed, &[], want, true).is_none() && !matches!(clarabel(&boxed, want), Ok(Some(_)))
}

/// Whether clarabel's failure beside the enumeration's `x` is clarabel's
/// own: it ended without a verdict (not solved, not infeasible: it ran
/// out of iterations or progress, which it does on some problems with
/// parallel rows, even with `want` feasible) and `x` meets every
/// (hard) row to rounding, so the rows are feasible; or its answer broke
/// a hard row by more than the check allows (clarabel's 1e-8 tolerances
/// scaled by `W` = 10⁶ in the relaxed problem) while `x` meets them; or,
/// when they meet only more than 10³ away (nearly parallel rows), it
/// declared them infeasible (to its tolerances).
fn clarabel_failed(
    status: &Result<Option<[f64; 2]>, SolverStatus>,
    hard: &[Constraint],
    x: [f64; 2],
) -> bool {
    let far = x[0].hypot(x[1]) > 1e3;
    let gave_up = match status {
        Err(SolverStatus::PrimalInfeasible) => far,
        Err(_) | Ok(_) => true,
    };
    gave_up && feasible(&Split(hard, &[]), x, Allowed::Rounding)
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(4000))]

    /// The enumeration's answer is clarabel's (objective within 1e-6,
    /// relative), and `None` exactly when clarabel's is (but on a
    /// knife's edge, see [`marginal`]).
    #[test]
    fn exact_solve_agrees_with_clarabel(
        rows in rows(),
        want in (-3.0..3.0f64, -3.0..3.0f64),
    ) {
        let want = [want.0, want.1];
        let new = split_with(&rows, &[], want, true);
        let status = clarabel(&rows, want);
        let old = status.unwrap_or(None);
        match (new, old) {
            (Some(x), Some(y)) => {
                let (fx, fy) = (objective(x, want), objective(y, want));
                // Clarabel's lower objective counts only if it met every
                // row to rounding (it meets them within its tolerance).
                let clarabel_broke = fy < fx && !feasible(&Split(&rows, &[]), y, Allowed::Rounding);
                prop_assert!(
                    (fx - fy).abs() <= 1e-6 * fx.max(fy).max(1.0) || clarabel_broke,
                    "exact {x:?} ({fx}) vs clarabel {y:?} ({fy})"
                );
                for c in &rows {
                    prop_assert!(c.slack(x) >= -TOLERANCE, "{c:?} at {x:?}");
                }
            }
            (None, None) => {}
            (Some(x), None) if clarabel_failed(&status, &rows, x) => {}
            (x, _) => prop_assert!(
                marginal(&rows, want),
                "exact {x:?} vs clarabel {status:?}"
            ),
        }
    }

    /// The same for the relaxed problem with a random soft/hard split.
    #[test]
    fn exact_relaxed_agrees_with_clarabel(
        rows in rows(),
        split in 0.0..=1.0f64,
        want in (-3.0..3.0f64, -3.0..3.0f64),
    ) {
        let want = [want.0, want.1];
        let soft_end = ((rows.len() as f64) * split).round() as usize;
        let new = relaxed_with(&rows, soft_end, want, true);
        let status = clarabel_relaxed(&rows, soft_end, want);
        let old = status.unwrap_or(None);
        match (new, old) {
            (Some(x), Some(y)) => {
                let fx = relaxed_objective(&rows, soft_end, x, want);
                let fy = relaxed_objective(&rows, soft_end, y, want);
                // The exact answer meets the hard rows (its objective,
                // with the least slack for the soft rows, is then
                // attained) and is never worse than clarabel's (1e-6).
                // Clarabel may be worse: its problem carries W s² (up to
                // ~1e11 here) and with nearly parallel rows its interior
                // point stops short (seen: 0.8 % above the exact answer).
                let scale = fx.max(fy).max(1.0);
                prop_assert!(
                    feasible(&Split(&rows[soft_end..], &[]), x, Allowed::Bound(TOLERANCE)),
                    "exact {x:?} breaks a hard row"
                );
                // Clarabel meets rows only within its tolerance: on a row
                // with a tiny coefficient (a [1, 5e-4] row pins x₂ at
                // ~500) that buys it objective (seen: 1.6e-6 relative).
                // Its lower objective counts only if it met the hard rows
                // to rounding.
                let clarabel_broke =
                    !feasible(&Split(&rows[soft_end..], &[]), y, Allowed::Rounding);
                prop_assert!(
                    fx - fy <= 1e-6 * scale || clarabel_broke,
                    "exact {x:?} ({fx}) vs clarabel {y:?} ({fy})"
                );
            }
            (None, None) => {}
            // The hard rows met to rounding prove the relaxed problem feasible (s
            // large enough meets the soft ones): clarabel, whose problem has
            // `W` = 10⁶ in it, failed (it also declares some such problems
            // infeasible, near `want`).
            (Some(x), None) if feasible(&Split(&rows[soft_end..], &[]), x, Allowed::Rounding) => {}
            (None, Some(_)) if meet_only_far(&rows[soft_end..], want) => {}
            (x, _) => prop_assert!(
                marginal_relaxed(&rows, soft_end, want),
                "exact {x:?} vs clarabel {status:?}"
            ),
        }
    }
}
