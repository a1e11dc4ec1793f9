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

mod fit;

pub use fit::{EB_RANGE, ED_RANGE};

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
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
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
    /// of gravity (removes the formulas' cross-coupling between `E_d` and `E_b`):
    /// the best fit over [`ED_RANGE`] × [`EB_RANGE`].
    pub refined: Systematic,
    /// How far the refined errors' centres of gravity are from the observed
    /// ones, root mean square over the four coordinates, m.
    pub fit_rms: f64,
    /// The standard error of the observed centres of gravity from the runs'
    /// scatter, root mean square over the four coordinates, m (0 with one run
    /// per direction, or runs that do not scatter).
    pub scatter: f64,
    /// Why the refined estimate may not be the robot's errors: the kinematics
    /// do not reproduce the runs, or other errors reproduce them as well.
    /// Empty when it is the one answer.
    pub warnings: Vec<String>,
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

/// How closely, relative to the return errors, the exact square kinematics
/// must reproduce runs that do not scatter (the model leaves out encoder
/// ticks and a real controller's path).
const MODEL_TOLERANCE: f64 = 2e-3;

/// How far `s` is from a perfect robot: the larger log-ratio of the two.
fn off_nominal(s: Systematic) -> f64 {
    s.ed.ln().abs().max(s.eb.ln().abs())
}

/// The centres of gravity of the CW and CCW return errors and the standard
/// error of each centre's coordinates, from the runs' spread.
fn centres(errors: &[ReturnError]) -> Result<([f64; 2], [f64; 2], f64), UmbmarkError> {
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
    let variance = |d: Direction, n: usize, mean: [f64; 2]| -> f64 {
        if n < 2 {
            return 0.0;
        }
        let sum: f64 = errors
            .iter()
            .filter(|e| e.direction == d)
            .map(|e| (e.ex - mean[0]).powi(2) + (e.ey - mean[1]).powi(2))
            .sum();
        sum / (n - 1) as f64 / n as f64
    };
    let scatter =
        (0.25 * (variance(Direction::Cw, ncw, cw) + variance(Direction::Ccw, nccw, ccw))).sqrt();
    Ok((cw, ccw, scatter))
}

/// How much better an alias beyond the ranges must reproduce the centres
/// than the refined estimate does to be reported however far it is from a
/// perfect robot: an in-range robot's runs are reproduced exactly (to
/// rounding) or to their scatter, which no other robot beats a hundredfold.
const BETTER_BEYOND: f64 = 100.0;

/// A warning when errors beyond the searched ranges reproduce the centres
/// `observed` within `tolerance` and are about as near a perfect robot
/// (`near`), or reproduce them [`BETTER_BEYOND`] times better than the
/// refined estimate (`refined_rms`): the runs may come from one of them (a
/// robot far out of its geometry drives return errors an in-range robot
/// nearly drives too: E_d = 0.599 and 1.353 at E_b = 0.888 on a 4 m
/// square, 2.4 mm apart on 3.4 m return errors; E_d = 0.544 at
/// E_b = 1.011 on a 7.4 m square drives whole circles on each leg and
/// returns within 0.1 m, as a robot of E_d = 1.0002 nearly does).
fn alias_beyond(
    clean: &SquareTest,
    observed: [f64; 4],
    first: Systematic,
    tolerance: f64,
    near: f64,
    refined_rms: f64,
) -> Option<String> {
    let beyond = fit::fits(clean, observed, first, &fit::BEYOND);
    let (other, rms) = beyond.iter().find(|(o, rms)| {
        !fit::inside(&fit::SEARCHED, [o.ed, o.eb])
            && *rms <= tolerance
            && (off_nominal(*o) <= near || *rms * BETTER_BEYOND < refined_rms)
    })?;
    Some(format!(
        "E_d = {:.6}, E_b = {:.6}, beyond the ranges the test tells apart (E_d in \
         [{}, {}], E_b in [{}, {}]), reproduces the centres of gravity as well ({} m \
         rms): the test cannot tell it from the refined estimate",
        other.ed,
        other.eb,
        ED_RANGE[0],
        ED_RANGE[1],
        EB_RANGE[0],
        EB_RANGE[1],
        crate::error::num(*rms),
    ))
}

/// Estimates `E_d`, `E_b` and the corrections from the return errors of runs on
/// the square of `geometry` (its side and the robot's nominal wheel radius and
/// half wheelbase; its error fields are ignored).
pub fn estimate(
    errors: &[ReturnError],
    geometry: &SquareTest,
) -> Result<Calibration, UmbmarkError> {
    let clean = geometry.one_run(ErrorModel::PERFECT);
    let (cw, ccw, scatter) = centres(errors)?;
    let wheelbase = 2.0 * geometry.half_wheelbase;
    let (alpha, beta, first) = borenstein(cw, ccw, geometry.side, wheelbase)?;
    let observed = [cw[0], cw[1], ccw[0], ccw[1]];
    let fits = fit::fits(&clean, observed, first, &fit::SEARCHED);
    // A fit reproduces the runs within three standard errors, or 0.2 % of
    // the return errors (encoder ticks, a controller's path: the exact
    // square is a model), or rounding.
    let size = (observed.iter().map(|o| o * o).sum::<f64>() / 4.0).sqrt();
    let tolerance = (3.0 * scatter)
        .max(MODEL_TOLERANCE * size)
        .max(1e-9 * geometry.side);
    // Of the fits that reproduce the runs, the one nearest a perfect robot
    // (runs that scatter also fit robots that drive whole circles on a leg);
    // none: the best, said not to be the robot's.
    let fitting = || fits.iter().filter(|(_, rms)| *rms <= tolerance);
    let mut warnings = Vec::new();
    let (refined, fit_rms) =
        match fitting().min_by(|a, b| off_nominal(a.0).total_cmp(&off_nominal(b.0))) {
            Some(&chosen) => chosen,
            None => {
                let best = fits.first().copied().unwrap_or((first, f64::INFINITY));
                warnings.push(format!(
                    "no E_d in [{}, {}] and E_b in [{}, {}] makes the exact square kinematics \
                 reproduce the centres of gravity: the best, E_d = {:.6}, E_b = {:.6}, misses \
                 them by {} m (rms; the runs' scatter allows {} m). The robot did not drive the \
                 test's square, or its errors are beyond what the test measures: the refined \
                 estimate and the corrections are not the robot's",
                    ED_RANGE[0],
                    ED_RANGE[1],
                    EB_RANGE[0],
                    EB_RANGE[1],
                    best.0.ed,
                    best.0.eb,
                    crate::error::num(best.1),
                    crate::error::num(tolerance),
                ));
                best
            }
        };
    // Others about as near a perfect robot, that fit as well: the test
    // cannot choose.
    let near = 2.0 * off_nominal(refined) + 0.01;
    for (other, rms) in fitting().filter(|(o, _)| *o != refined && off_nominal(*o) <= near) {
        warnings.push(format!(
            "E_d = {:.6}, E_b = {:.6} reproduces the centres of gravity as well ({} m rms): \
             the test cannot tell it from the refined estimate",
            other.ed,
            other.eb,
            crate::error::num(*rms),
        ));
    }
    // Errors beyond the searched ranges that reproduce the runs as well and
    // are about as near a perfect robot (the rule above): the runs may come
    // from one of them (a robot far out of its geometry drives return errors
    // an in-range robot nearly drives too: E_d = 0.599 and 1.353 at
    // E_b = 0.888 on a 4 m square, 2.4 mm apart on 3.4 m return errors).
    if warnings.is_empty() {
        warnings.extend(alias_beyond(
            &clean, observed, first, tolerance, near, fit_rms,
        ));
    }
    Ok(Calibration {
        cg_cw: cw,
        cg_ccw: ccw,
        alpha,
        beta,
        borenstein: first,
        refined,
        fit_rms,
        scatter,
        warnings,
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
mod tests;
