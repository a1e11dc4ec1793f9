//! Borenstein's UMBmark (Borenstein & Feng, 1996): the bidirectional square test
//! that measures a robot's systematic odometry errors — unequal wheel diameters
//! `E_d` and a wrong wheelbase `E_b` — from where it really ends after driving a
//! square clockwise and counter-clockwise by its own odometry.
//!
//! The simulation here is exact kinematics: the robot drives each leg and each
//! 90° turn until its encoders (read with the nominal wheel radius and
//! wheelbase) say it is done; its true motion follows from the actual wheels.
//! Slip and tick quantization add the run-to-run scatter of a real test.

use rand::{Rng, SeedableRng};
pub use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;

use crate::error::ParamError;
use crate::model::{Pose, RobotParams};
use crate::odometry::{ErrorModel, WheelDisplacement, dead_reckon};

/// Direction of a square run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Direction {
    /// Clockwise: every turn is to the right.
    Cw,
    /// Counter-clockwise: every turn is to the left.
    Ccw,
}

/// One run's return position error: true end minus odometry's end, m, in the
/// start frame (the robot starts at the origin heading along +x).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct ReturnError {
    /// Direction of the run.
    pub direction: Direction,
    /// Run number within its direction (from 1).
    pub run: usize,
    /// `ε_x`, m.
    pub ex: f64,
    /// `ε_y`, m.
    pub ey: f64,
}

/// A simulated UMBmark test. Built by [`SquareTest::borenstein`] and
/// [`SquareTest::with_square`], which refuse an impossible square.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SquareTest {
    side: f64,
    runs: usize,
    wheel_radius: f64,
    half_wheelbase: f64,
    errors: ErrorModel,
    seed: u64,
}

impl SquareTest {
    /// Borenstein's test (a 4 m square, 5 runs each way) of a robot with the
    /// nominal wheels of `robot` and the actual `errors` (`E_d`, `E_b`,
    /// slip, ticks; its other errors are unused); `seed` draws the slip.
    pub const fn borenstein(robot: &RobotParams, errors: ErrorModel, seed: u64) -> SquareTest {
        SquareTest {
            side: 4.0,
            runs: 5,
            wheel_radius: robot.wheel_radius(),
            half_wheelbase: robot.half_wheelbase(),
            errors,
            seed,
        }
    }

    /// This test on a square of side `side` m (finite, > 0), `runs` runs in
    /// each direction (≥ 1).
    pub fn with_square(self, side: f64, runs: usize) -> Result<SquareTest, ParamError> {
        crate::check::at_least_one("runs", runs as u64)?;
        Ok(SquareTest {
            side: crate::check::positive("side", side)?,
            runs,
            ..self
        })
    }

    /// Side of the square `L`, m.
    pub const fn side(&self) -> f64 {
        self.side
    }

    /// Runs in each direction.
    pub const fn runs(&self) -> usize {
        self.runs
    }

    /// The robot's nominal wheel radius `r`, m.
    pub const fn wheel_radius(&self) -> f64 {
        self.wheel_radius
    }

    /// The robot's actual errors.
    pub const fn errors(&self) -> ErrorModel {
        self.errors
    }

    /// This test's geometry with one run and other errors.
    const fn one_run(&self, errors: ErrorModel) -> SquareTest {
        SquareTest {
            runs: 1,
            errors,
            ..*self
        }
    }

    /// Drives every run and returns the return errors, CW runs first.
    pub fn simulate(&self) -> Vec<ReturnError> {
        let mut rng = ChaCha8Rng::seed_from_u64(self.seed);
        let mut out = Vec::with_capacity(2 * self.runs);
        for direction in [Direction::Cw, Direction::Ccw] {
            for run in 1..=self.runs {
                let (truth, believed) = self.drive(direction, &mut rng);
                out.push(ReturnError {
                    direction,
                    run,
                    ex: truth.x - believed.x,
                    ey: truth.y - believed.y,
                });
            }
        }
        out
    }

    /// One square: four legs, each followed by a 90° turn on the spot; returns
    /// the true and the believed end poses.
    fn drive(&self, direction: Direction, rng: &mut ChaCha8Rng) -> (Pose, Pose) {
        let path = self.trace(direction, rng);
        path[path.len() - 1]
    }

    /// The true and believed poses at the start and after each leg and turn of
    /// one square (9 pairs), with slip drawn from `rng`.
    pub fn trace(&self, direction: Direction, rng: &mut ChaCha8Rng) -> Vec<(Pose, Pose)> {
        let e = &self.errors;
        let (rr, rl) = e.wheel_radii(self.wheel_radius);
        let actual_l = self.half_wheelbase * e.wheelbase_ratio();
        let sign = match direction {
            Direction::Ccw => 1.0,
            Direction::Cw => -1.0,
        };
        let turn = sign * self.half_wheelbase * std::f64::consts::FRAC_PI_2;
        let mut truth = Pose::default();
        let mut believed = Pose::default();
        let mut path = Vec::with_capacity(9);
        path.push((truth, believed));
        for _ in 0..4 {
            for (right, left) in [(self.side, self.side), (turn, -turn)] {
                // The commanded wheel rotations, as the encoders count them.
                let angles = [right, left].map(|d| self.encoder_angle(d));
                let measured = angles.map(|a| a * self.wheel_radius);
                let mut travel = [angles[0] * rr, angles[1] * rl];
                if e.slip() > 0.0 {
                    for t in &mut travel {
                        let noise: f64 = rng.sample(StandardNormal);
                        *t += noise * (e.slip() * t.abs()).sqrt();
                    }
                }
                truth = dead_reckon(
                    &truth,
                    WheelDisplacement {
                        right: travel[0],
                        left: travel[1],
                    },
                    actual_l,
                );
                believed = dead_reckon(
                    &believed,
                    WheelDisplacement {
                        right: measured[0],
                        left: measured[1],
                    },
                    self.half_wheelbase,
                );
                path.push((truth, believed));
            }
        }
        path
    }

    /// The wheel rotation (rad) at which the drive stops for a commanded
    /// displacement `d`: the nearest whole tick with real encoders.
    fn encoder_angle(&self, d: f64) -> f64 {
        let angle = d / self.wheel_radius;
        match self.errors.ticks_per_rev() {
            None => angle,
            Some(n) => {
                let per_tick = std::f64::consts::TAU / f64::from(n);
                (angle / per_tick).round() * per_tick
            }
        }
    }
}

/// Estimated systematic errors.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Systematic {
    /// `E_d = D_R / D_L`.
    pub ed: f64,
    /// `E_b = b_actual / b_nominal`.
    pub eb: f64,
}

/// What a UMBmark test concludes.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Calibration {
    /// Centre of gravity of the CW return errors `(x, y)`, m.
    pub cg_cw: [f64; 2],
    /// Centre of gravity of the CCW return errors `(x, y)`, m.
    pub cg_ccw: [f64; 2],
    /// Borenstein's type A error `α` (wheelbase), rad.
    pub alpha: f64,
    /// Borenstein's type B error `β` (wheel diameters), rad.
    pub beta: f64,
    /// Borenstein's closed-form estimate (first order in the errors).
    pub borenstein: Systematic,
    /// The estimate refined by fitting the exact square kinematics to the centres
    /// of gravity (removes the formulas' cross-coupling between `E_d` and `E_b`).
    pub refined: Systematic,
    /// Correction factor for the left wheel's diameter, `c_L = 2/(E_d + 1)`.
    pub c_left: f64,
    /// Correction factor for the right wheel's diameter, `c_R = 2/(1/E_d + 1)`.
    pub c_right: f64,
    /// Corrected wheelbase `E_b b_nominal`, m.
    pub wheelbase: f64,
}

/// Why the return errors cannot be turned into an estimate.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum UmbmarkError {
    /// Runs in only one direction.
    #[error("UMBmark needs runs in both directions (clockwise: {cw}, counter-clockwise: {ccw})")]
    OneDirection {
        /// Number of CW runs.
        cw: usize,
        /// Number of CCW runs.
        ccw: usize,
    },
    /// Errors too large for the small-error formulas.
    #[error("the return errors are too large for Borenstein's formulas (|β/2| = {0} rad ≥ π/2)")]
    TooLarge(f64),
    /// No `E_d`, `E_b` in the range the test can tell apart reproduces the
    /// centres of gravity within the runs' scatter.
    #[error(
        "no E_d, E_b in {} to {} reproduces the return errors: the closest misses the centres of gravity by {misfit:.3e} m (RMS), where the runs' scatter allows {allowed:.3e} m{note} (runs of robots that differ, or errors beyond what the square test measures)",
        PLAUSIBLE.0,
        PLAUSIBLE.1
    )]
    NoFit {
        /// RMS distance of the best fit's centres of gravity from the observed, m.
        misfit: f64,
        /// What the scatter of the runs allows, m.
        allowed: f64,
        /// `, and a single run in a direction shows no scatter` when so.
        note: &'static str,
    },
}

/// The `E_d`, `E_b` the refinement searches (the scenario's plausible range
/// for both). At `E_b = 0.5` the robot turns 180° for 90°, the square folds
/// onto a line and its return errors are those of a perfect robot: the
/// lower end is open.
const PLAUSIBLE: (f64, f64) = (0.5, 2.0);

/// Starts of the refinement per axis, on a geometric grid over [`PLAUSIBLE`]
/// (besides Borenstein's estimate): Gauss–Newton from his estimate alone
/// stopped in a wrong local minimum once the errors were a few per cent
/// (`E_d = 1.1` gave 0.89, with `E_b = 0.44` for 1), whose return errors
/// miss the observed ones by a metre.
const STARTS: usize = 9;

/// Whether `s` is in the range the refinement searches.
fn searched(s: Systematic) -> bool {
    let (lo, hi) = PLAUSIBLE;
    (lo..=hi).contains(&s.ed) && s.eb > lo && s.eb <= hi
}

/// Borenstein's formulas (Borenstein & Feng 1996) for a square of side `L` and
/// nominal wheelbase `b = 2l`, from the centres of gravity of the return errors:
///
/// ```text
/// α = (x_cg,cw + x_cg,ccw) / (−4L)          β = (x_cg,cw − x_cg,ccw) / (−4L)
/// R = (L/2) / sin(β/2)                      E_d = (R + b/2) / (R − b/2)
/// E_b = (π/2) / (π/2 − α)
/// ```
fn borenstein(
    cw: [f64; 2],
    ccw: [f64; 2],
    side: f64,
    wheelbase: f64,
) -> Result<(f64, f64, Systematic), UmbmarkError> {
    let alpha = (cw[0] + ccw[0]) / (-4.0 * side);
    let beta = (cw[0] - ccw[0]) / (-4.0 * side);
    let half_b = 0.5 * wheelbase;
    let ed = if beta == 0.0 {
        1.0
    } else {
        if (0.5 * beta).abs() >= std::f64::consts::FRAC_PI_2 {
            return Err(UmbmarkError::TooLarge((0.5 * beta).abs()));
        }
        let r = 0.5 * side / (0.5 * beta).sin();
        (r + half_b) / (r - half_b)
    };
    let eb = std::f64::consts::FRAC_PI_2 / (std::f64::consts::FRAC_PI_2 - alpha);
    Ok((alpha, beta, Systematic { ed, eb }))
}

/// The centres of gravity `[x_cw, y_cw, x_ccw, y_ccw]` an error-free-but-systematic
/// robot would produce: the model the refinement inverts (`None` for
/// impossible errors, `E_d` or `E_b` ≤ 0).
fn model(geometry: &SquareTest, s: Systematic) -> Option<[f64; 4]> {
    let t = geometry.one_run(ErrorModel::systematic(s.ed, s.eb).ok()?);
    let mut rng = ChaCha8Rng::seed_from_u64(0);
    let (a, b) = (
        t.drive(Direction::Cw, &mut rng),
        t.drive(Direction::Ccw, &mut rng),
    );
    Some([a.0.x - a.1.x, a.0.y - a.1.y, b.0.x - b.1.x, b.0.y - b.1.y])
}

/// RMS distance of the centres of gravity the model gives at `s` from
/// `observed`, m (`None` for impossible errors).
fn misfit(geometry: &SquareTest, observed: [f64; 4], s: Systematic) -> Option<f64> {
    let f = model(geometry, s)?;
    let sum: f64 = f.iter().zip(observed).map(|(a, b)| (a - b).powi(2)).sum();
    Some((0.25 * sum).sqrt())
}

/// Gauss-Newton on `(E_d, E_b)` so that the exact square kinematics reproduce
/// the observed centres of gravity, from Borenstein's estimate (kept when
/// the fit leaves the possible errors).
fn refine(geometry: &SquareTest, observed: [f64; 4], start: Systematic) -> Systematic {
    let mut p = [start.ed, start.eb];
    for _ in 0..20 {
        let Some(f) = model(geometry, Systematic { ed: p[0], eb: p[1] }) else {
            return start;
        };
        let r: [f64; 4] = std::array::from_fn(|i| f[i] - observed[i]);
        // Jacobian by central differences of the (smooth) kinematic model.
        let h = 1e-6;
        let mut j = [[0.0; 2]; 4];
        for k in 0..2 {
            let mut lo = p;
            let mut hi = p;
            lo[k] -= h;
            hi[k] += h;
            let at = |q: [f64; 2]| model(geometry, Systematic { ed: q[0], eb: q[1] });
            let (Some(fl), Some(fh)) = (at(lo), at(hi)) else {
                return start;
            };
            for i in 0..4 {
                j[i][k] = (fh[i] - fl[i]) / (2.0 * h);
            }
        }
        // Normal equations (JᵀJ) δ = −Jᵀr.
        let mut a = [[0.0; 2]; 2];
        let mut g = [0.0; 2];
        for i in 0..4 {
            for k in 0..2 {
                g[k] -= j[i][k] * r[i];
                for m in 0..2 {
                    a[k][m] += j[i][k] * j[i][m];
                }
            }
        }
        let det = a[0][0] * a[1][1] - a[0][1] * a[1][0];
        if det.abs() < 1e-300 {
            break;
        }
        let d = [
            (a[1][1] * g[0] - a[0][1] * g[1]) / det,
            (a[0][0] * g[1] - a[1][0] * g[0]) / det,
        ];
        p = [p[0] + d[0], p[1] + d[1]];
        if !(p[0] > 0.0 && p[1] > 0.0) {
            return start;
        }
        if d[0].abs().max(d[1].abs()) < 1e-12 {
            break;
        }
    }
    Systematic { ed: p[0], eb: p[1] }
}

/// Estimates `E_d`, `E_b` and the corrections from the return errors of runs on
/// the square of `geometry` (its side and the robot's nominal wheel radius and
/// half wheelbase; its error fields are ignored).
pub fn estimate(
    errors: &[ReturnError],
    geometry: &SquareTest,
) -> Result<Calibration, UmbmarkError> {
    let clean = geometry.one_run(ErrorModel::PERFECT);
    let centroid = |d: Direction| -> (usize, [f64; 2]) {
        let (n, sum) = errors
            .iter()
            .filter(|e| e.direction == d)
            .fold((0, [0.0, 0.0]), |(n, a), e| {
                (n + 1, [a[0] + e.ex, a[1] + e.ey])
            });
        (n, [sum[0] / n.max(1) as f64, sum[1] / n.max(1) as f64])
    };
    let (ncw, cw) = centroid(Direction::Cw);
    let (nccw, ccw) = centroid(Direction::Ccw);
    if ncw == 0 || nccw == 0 {
        return Err(UmbmarkError::OneDirection { cw: ncw, ccw: nccw });
    }
    let wheelbase = 2.0 * geometry.half_wheelbase;
    let (alpha, beta, first) = borenstein(cw, ccw, geometry.side, wheelbase)?;
    let observed = [cw[0], cw[1], ccw[0], ccw[1]];
    // What the runs' scatter allows the fit to miss by: three standard
    // errors of the centres of gravity, and at least a part in 10⁹ of the
    // side (rounding).
    let spread = |d: Direction, c: [f64; 2]| -> (f64, usize) {
        errors
            .iter()
            .filter(|e| e.direction == d)
            .fold((0.0, 0), |(s, n), e| {
                (s + (e.ex - c[0]).powi(2) + (e.ey - c[1]).powi(2), n + 1)
            })
    };
    let ((s_cw, n_cw), (s_ccw, n_ccw)) = (spread(Direction::Cw, cw), spread(Direction::Ccw, ccw));
    // Variance of each centre's coordinate, over the four coordinates.
    let var = |s: f64, n: usize| {
        if n > 1 {
            s / (2.0 * (n - 1) as f64 * n as f64)
        } else {
            0.0
        }
    };
    let se = (0.5 * (var(s_cw, n_cw) + var(s_ccw, n_ccw))).sqrt();
    // Encoder ticks stop each leg and turn up to half a tick off, which the
    // model (ideal encoders) does not have: a heading off by up to a tick of
    // one wheel over the wheelbase at each of four corners, over the side.
    let ticks = geometry.errors.ticks_per_rev().map_or(0.0, |n| {
        let tick = std::f64::consts::TAU * geometry.wheel_radius / f64::from(n);
        4.0 * geometry.side * tick / (2.0 * geometry.half_wheelbase)
    });
    let allowed = (3.0 * se).max(1e-9 * geometry.side) + ticks;
    let (lo, hi) = PLAUSIBLE;
    let grid = |k: usize| lo * (hi / lo).powf(k as f64 / (STARTS - 1) as f64);
    let starts = std::iter::once(first).chain((0..STARTS).flat_map(|i| {
        (0..STARTS).map(move |j| Systematic {
            ed: grid(i),
            eb: grid(j),
        })
    }));
    let fits: Vec<(Systematic, f64)> = starts
        .map(|s| refine(&clean, observed, s))
        .filter(|s| searched(*s))
        .filter_map(|s| misfit(&clean, observed, s).map(|m| (s, m)))
        .collect();
    // Large errors have aliases (a perfect robot's return errors are also
    // those of E_d = 0.57, E_b = 0.67, whose corners turn 135°): of the fits
    // that reproduce the runs, the one nearest a perfect robot, which is
    // what the test measures (small errors).
    let from_perfect = |s: &Systematic| s.ed.ln().abs().max(s.eb.ln().abs());
    let Some(&(refined, _)) = fits
        .iter()
        .filter(|(_, m)| *m <= allowed)
        .min_by(|a, b| from_perfect(&a.0).total_cmp(&from_perfect(&b.0)))
    else {
        let best = fits.iter().map(|f| f.1).fold(f64::INFINITY, f64::min);
        return Err(UmbmarkError::NoFit {
            misfit: best,
            allowed,
            note: if n_cw.min(n_ccw) < 2 {
                ", and a single run in a direction shows no scatter"
            } else {
                ""
            },
        });
    };

    Ok(Calibration {
        cg_cw: cw,
        cg_ccw: ccw,
        alpha,
        beta,
        borenstein: first,
        refined,
        c_left: 2.0 / (refined.ed + 1.0),
        c_right: 2.0 / (1.0 / refined.ed + 1.0),
        wheelbase: refined.eb * wheelbase,
    })
}

/// Return errors from recorded runs: each directory holds a run's
/// `trajectory.csv` (the truth) and `odometry.csv` (what the robot believed).
/// Every dead-reckoning agent's run gives one return error — its true final
/// position minus its estimated one, in its start frame — and its direction is
/// the sign of its estimated total turn.
pub fn from_logs(
    dirs: &[std::path::PathBuf],
) -> Result<Vec<ReturnError>, crate::error::OutputError> {
    use crate::output::{ODOMETRY_FILE, TRAJECTORY_FILE, Table};
    let mut out = Vec::new();
    let (mut ncw, mut nccw) = (0, 0);
    for dir in dirs {
        let (tp, op) = (dir.join(TRAJECTORY_FILE), dir.join(ODOMETRY_FILE));
        let (traj, odo) = (Table::read(&tp)?, Table::read(&op)?);
        let ta = traj.column("agent", &tp)?;
        let [tx, ty, tt] = ["x", "y", "theta"].map(|c| traj.column(c, &tp));
        let (tx, ty, tt) = (tx?, ty?, tt?);
        let oa = odo.column("agent", &op)?;
        let [ox, oy, ot] = ["x_hat", "y_hat", "theta_hat"].map(|c| odo.column(c, &op));
        let (ox, oy, ot) = (ox?, oy?, ot?);
        let mut agents: Vec<f64> = odo.rows.iter().map(|r| r[oa]).collect();
        agents.sort_by(f64::total_cmp);
        agents.dedup();
        for agent in agents {
            let truth: Vec<&Vec<f64>> = traj.rows.iter().filter(|r| r[ta] == agent).collect();
            let est: Vec<&Vec<f64>> = odo.rows.iter().filter(|r| r[oa] == agent).collect();
            let (Some(first), Some(last), Some(last_est)) =
                (truth.first(), truth.last(), est.last())
            else {
                return Err(crate::error::OutputError::Parse {
                    path: tp.clone(),
                    line: 0,
                    message: format!("agent {agent} has odometry rows but no trajectory rows"),
                });
            };
            // Total estimated turn, unwrapping the logged headings.
            let turn: f64 = est
                .windows(2)
                .map(|w| crate::model::wrap_angle(w[1][ot] - w[0][ot]))
                .sum();
            let direction = if turn < 0.0 {
                Direction::Cw
            } else {
                Direction::Ccw
            };
            let (s, c) = first[tt].sin_cos();
            let (dx, dy) = (last[tx] - last_est[ox], last[ty] - last_est[oy]);
            let run = match direction {
                Direction::Cw => {
                    ncw += 1;
                    ncw
                }
                Direction::Ccw => {
                    nccw += 1;
                    nccw
                }
            };
            out.push(ReturnError {
                direction,
                run,
                ex: c * dx + s * dy,
                ey: -s * dx + c * dy,
            });
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 4 m square test of Table I agent 1's geometry.
    fn square(ed: f64, eb: f64, slip: f64, ticks: Option<u32>, seed: u64) -> SquareTest {
        let errors = ErrorModel::systematic(ed, eb)
            .and_then(|e| e.with_slip(slip))
            .and_then(|e| e.with_ticks_per_rev(ticks))
            .unwrap();
        SquareTest::borenstein(&RobotParams::AGENT1, errors, seed)
    }

    fn test(ed: f64, eb: f64) -> SquareTest {
        square(ed, eb, 0.0, None, 1)
    }

    #[test]
    fn a_perfect_robot_returns_exactly() {
        let errs = test(1.0, 1.0).simulate();
        assert!(
            errs.iter()
                .all(|e| e.ex.abs() < 1e-12 && e.ey.abs() < 1e-12)
        );
        let c = estimate(&errs, &test(1.0, 1.0)).unwrap();
        assert!((c.refined.ed - 1.0).abs() < 1e-12 && (c.refined.eb - 1.0).abs() < 1e-12);
        assert!((c.borenstein.ed - 1.0).abs() < 1e-12 && (c.borenstein.eb - 1.0).abs() < 1e-12);
    }

    #[test]
    fn one_direction_is_refused() {
        let errs: Vec<ReturnError> = test(1.01, 1.0)
            .simulate()
            .into_iter()
            .filter(|e| e.direction == Direction::Cw)
            .collect();
        assert!(matches!(
            estimate(&errs, &test(1.0, 1.0)),
            Err(UmbmarkError::OneDirection { cw: 5, ccw: 0 })
        ));
    }

    fn run(ed: f64, eb: f64, slip: f64, ticks: Option<u32>, seed: u64) -> Calibration {
        let t = square(ed, eb, slip, ticks, seed);
        estimate(&t.simulate(), &t).unwrap()
    }

    /// The relative error of the estimated deviation from a perfect robot.
    fn off(est: f64, truth: f64) -> f64 {
        ((est - 1.0) - (truth - 1.0)).abs() / (truth - 1.0).abs()
    }

    #[test]
    fn refined_estimate_recovers_systematic_errors_exactly_without_noise() {
        for (ed, eb) in [
            (1.01, 1.0),
            (1.0, 1.02),
            (0.99, 0.98),
            (1.005, 1.01),
            (0.996, 1.03),
        ] {
            let c = run(ed, eb, 0.0, None, 1);
            if ed != 1.0 {
                assert!(off(c.refined.ed, ed) < 1e-6, "E_d {ed}: {}", c.refined.ed);
            }
            if eb != 1.0 {
                assert!(off(c.refined.eb, eb) < 1e-6, "E_b {eb}: {}", c.refined.eb);
            }
        }
    }

    #[test]
    fn borensteins_formulas_are_first_order() {
        // Small errors: the closed form is within 10 % of the injected deviations…
        let c = run(1.002, 1.01, 0.0, None, 1);
        assert!(
            off(c.borenstein.ed, 1.002) < 0.1 && off(c.borenstein.eb, 1.01) < 0.1,
            "{c:?}"
        );
        // …larger ones couple E_d into E_b, which the refinement removes.
        let c = run(1.005, 1.01, 0.0, None, 1);
        assert!(off(c.borenstein.eb, 1.01) > 0.1);
        assert!(off(c.refined.eb, 1.01) < 1e-6);
    }
}
