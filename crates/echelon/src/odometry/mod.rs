//! Odometry (paper section 6): wheel encoders, dead reckoning, error models,
//! absolute position fixes and the estimate the controller acts on.
//!
//! Each sample the encoders give the wheels' displacements `Δr`, `Δl`; dead
//! reckoning integrates them (eqs. 21–22). The robot's true motion comes from
//! the plant, so everything that makes the encoders lie — the paper's additive
//! `ζ` (Assumption 1, eq. 23), Borenstein's unequal wheel diameters `E_d` and
//! wheelbase error `E_b`, random slip, tick quantization — makes the estimate
//! drift from the truth. Absolute fixes (every `N` samples or `T` seconds, with
//! noise and latency) reset the estimate (the paper) or feed an EKF.
//!
//! [`bound`] is Theorem 2, [`umbmark`] Borenstein's calibration test.

pub mod bound;
mod ekf;
pub mod fuse;
pub mod umbmark;

use std::collections::VecDeque;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;

use crate::check;
use crate::error::ParamError;
use crate::math::sinc;
use crate::model::{Pose, RobotParams, State};

pub use ekf::Ekf;
use fuse::{FixFusion, FixNoise};

/// Linear displacements of the two wheels over one sample, m.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct WheelDisplacement {
    /// Right wheel `Δr`.
    pub right: f64,
    /// Left wheel `Δl`.
    pub left: f64,
}

impl WheelDisplacement {
    /// `Δ = (Δr + Δl)/2` and `Θ = (Δr − Δl)/(2l)` (eq. 21).
    #[inline]
    pub fn to_motion(self, half_wheelbase: f64) -> (f64, f64) {
        (
            0.5 * (self.right + self.left),
            (self.right - self.left) / (2.0 * half_wheelbase),
        )
    }
}

/// One dead-reckoning update (eq. 22) by the linear displacement `Δ` and the
/// heading change `Θ`, along the exact arc. Eq. 22's `(Δ/Θ)(sin θₙ − sin θₙ₋₁)` is
/// computed as `Δ sinc(Θ/2) cos(θₙ₋₁ + Θ/2)`, which is the same number without the
/// division (and is eq. 22's straight-line branch at `Θ = 0`).
#[inline]
pub fn arc_update(pose: &Pose, delta: f64, big_theta: f64) -> Pose {
    let chord = delta * sinc(0.5 * big_theta);
    let (s, c) = (pose.theta + 0.5 * big_theta).sin_cos();
    Pose {
        x: pose.x + chord * c,
        y: pose.y + chord * s,
        theta: pose.theta + big_theta,
    }
}

/// The inverse of [`arc_update`]: the `(Δ, Θ)` of the arc from `from` to
/// `to` (a motion that is not an arc from `from`'s heading, e.g. a sideways
/// slip, gets the arc with the same chord length and heading change; the
/// sign of `Δ` is that of the chord along the arc's mid heading). For `|Θ| <
/// 2π`.
pub fn arc_motion(from: &Pose, to: &Pose) -> (f64, f64) {
    let big_theta = to.theta - from.theta;
    let (dx, dy) = (to.x - from.x, to.y - from.y);
    let (s, c) = (from.theta + 0.5 * big_theta).sin_cos();
    let along = dx * c + dy * s;
    let chord = dx.hypot(dy).copysign(along);
    (chord / sinc(0.5 * big_theta), big_theta)
}

/// Dead reckoning from wheel displacements: eq. 21 then eq. 22.
#[inline]
pub fn dead_reckon(pose: &Pose, d: WheelDisplacement, half_wheelbase: f64) -> Pose {
    let (delta, big_theta) = d.to_motion(half_wheelbase);
    arc_update(pose, delta, big_theta)
}

/// How the paper's additive error `ζ` enters (`zeta_model = "wheels"` or
/// `"worst-case"` in a scenario).
#[derive(
    Debug,
    Clone,
    Copy,
    PartialEq,
    Eq,
    Default,
    serde::Deserialize,
    serde::Serialize,
    schemars::JsonSchema,
)]
#[serde(rename_all = "kebab-case")]
pub enum ZetaModel {
    /// Assumption 1, eq. 23: each wheel's true displacement exceeds the measured
    /// one by `ζ` every sample, so `Δ = Δ̂ + ζ`, `Θ = Θ̂` (eq. 24): the heading
    /// stays exact and the position drifts by at most `ζ` per axis per sample.
    #[default]
    Wheels,
    /// The worst case of eq. 31: the true position exceeds the estimate by `ζ`
    /// on both world axes every sample (`x_N = x̂_N + Nζ`, `y_N = ŷ_N + Nζ`), the
    /// case Theorem 2 is written for.
    WorstCase,
}

/// The errors of one robot's odometry. All default to a perfect odometer.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ErrorModel {
    /// The paper's additive error `ζ`, m per sample (eq. 23).
    pub zeta: f64,
    /// How `ζ` enters.
    pub zeta_model: ZetaModel,
    /// Borenstein's `E_d = D_R / D_L`, the ratio of the actual wheel diameters
    /// (their mean is the nominal one). 1 is perfect.
    pub wheel_diameter_ratio: f64,
    /// Borenstein's `E_b = b_actual / b_nominal`, the actual over the nominal
    /// wheelbase. 1 is perfect.
    pub wheelbase_ratio: f64,
    /// Random slip: each wheel's measured displacement gets Gaussian noise of
    /// variance `slip · |Δ|`, m²/m (variance per metre travelled).
    pub slip: f64,
    /// Encoder resolution, ticks per wheel revolution (`None`: ideal encoders).
    pub ticks_per_rev: Option<u32>,
    /// Standard deviation of the measured linear speed, m/s (Assumption 2: speeds
    /// are measured directly; 0 is exact).
    pub speed_noise: f64,
    /// Standard deviation of the measured angular speed, rad/s.
    pub turn_rate_noise: f64,
}

impl Default for ErrorModel {
    fn default() -> Self {
        ErrorModel::PERFECT
    }
}

impl ErrorModel {
    /// Perfect encoders and speed measurements.
    pub const PERFECT: ErrorModel = ErrorModel {
        zeta: 0.0,
        zeta_model: ZetaModel::Wheels,
        wheel_diameter_ratio: 1.0,
        wheelbase_ratio: 1.0,
        slip: 0.0,
        ticks_per_rev: None,
        speed_noise: 0.0,
        turn_rate_noise: 0.0,
    };

    /// Only Borenstein's systematic errors: the wheel diameter ratio `E_d`
    /// and the wheelbase ratio `E_b`, everything else perfect.
    pub const fn systematic(ed: f64, eb: f64) -> ErrorModel {
        ErrorModel {
            wheel_diameter_ratio: ed,
            wheelbase_ratio: eb,
            ..ErrorModel::PERFECT
        }
    }

    /// Refuses non-finite values, negative variances and ratios ≤ 0.
    pub fn validate(&self) -> Result<(), ParamError> {
        for (field, v) in [
            ("zeta", self.zeta),
            ("wheel_diameter_ratio", self.wheel_diameter_ratio),
            ("wheelbase_ratio", self.wheelbase_ratio),
            ("slip", self.slip),
            ("speed_noise", self.speed_noise),
            ("turn_rate_noise", self.turn_rate_noise),
        ] {
            check::finite(field, v)?;
        }
        for (field, v) in [
            ("wheel_diameter_ratio", self.wheel_diameter_ratio),
            ("wheelbase_ratio", self.wheelbase_ratio),
        ] {
            check::require(field, v, v > 0.0, "must be > 0 (1 is a perfect robot)")?;
        }
        for (field, v) in [
            ("slip", self.slip),
            ("speed_noise", self.speed_noise),
            ("turn_rate_noise", self.turn_rate_noise),
        ] {
            check::require(field, v, v >= 0.0, "must be ≥ 0")?;
        }
        if let Some(n) = self.ticks_per_rev {
            check::at_least_one("ticks_per_rev", n.into())?;
        }
        Ok(())
    }

    /// Variance of each wheel's measured displacement in a sample in which
    /// the wheels (radius `r`) travelled `step` (right, left), m²: slip plus
    /// the quantization of the encoders (uniform over one tick) plus `ζ²`,
    /// plus a floor that keeps a filter from trusting odometry absolutely.
    pub fn wheel_variance(&self, r: f64, step: [f64; 2]) -> [f64; 2] {
        let tick = self.tick(r).powi(2) / 6.0;
        let zeta = self.zeta * self.zeta;
        let floor = 1e-12;
        step.map(|d| self.slip * d.abs() + tick + zeta + floor)
    }

    /// One encoder tick of a wheel of radius `r`, m (0: ideal encoders).
    fn tick(&self, r: f64) -> f64 {
        self.ticks_per_rev
            .map_or(0.0, |n| std::f64::consts::TAU * r / f64::from(n))
    }

    /// Theorem 2's `ζ` for this model: a bound on the position error per
    /// axis of one sample in which the robot (wheels of radius `r`)
    /// travelled `step` m, under the theorem's Assumption 1 (the heading
    /// exact): the additive `ζ`, plus three standard deviations of the
    /// slip on the mean wheel displacement (`3 √(slip · step / 2)`), plus
    /// one encoder tick. The systematic `E_d`, `E_b` turn the heading and
    /// are outside Assumption 1; fixes that carry a heading correct them.
    pub fn zeta_per_sample(&self, r: f64, step: f64) -> f64 {
        let slip = if self.slip > 0.0 {
            3.0 * (self.slip * step.abs() / 2.0).sqrt()
        } else {
            0.0
        };
        self.zeta + slip + self.tick(r)
    }

    /// Actual right and left wheel radii for nominal radius `r` (Borenstein: the
    /// mean diameter is nominal, `D_R/D_L = E_d`).
    pub fn wheel_radii(&self, r: f64) -> (f64, f64) {
        let e = self.wheel_diameter_ratio;
        (r * 2.0 * e / (e + 1.0), r * 2.0 / (e + 1.0))
    }
}

/// When absolute fixes are taken.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum FixSchedule {
    /// Every `N` odometry samples (the paper's `N`).
    EverySamples(u64),
    /// Every `T` seconds (a whole number of odometry samples).
    Period(f64),
}

/// How a fix corrects the estimate (`fusion = "reset"` or `"ekf"` in a scenario).
#[derive(
    Debug,
    Clone,
    Copy,
    PartialEq,
    Eq,
    Default,
    serde::Deserialize,
    serde::Serialize,
    schemars::JsonSchema,
)]
#[serde(rename_all = "kebab-case")]
pub enum Fusion {
    /// Replace the estimate by the fix (the paper's "recalibration").
    #[default]
    Reset,
    /// Fuse odometry and fixes in an extended Kalman filter.
    Ekf,
}

/// Absolute position fixes (a motion-capture system, GNSS, a beacon…).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FixSpec {
    /// When.
    pub schedule: FixSchedule,
    /// Standard deviation of each position coordinate, m.
    pub position_noise: f64,
    /// Standard deviation of the heading, rad (`None`: fixes give no heading).
    pub heading_noise: Option<f64>,
    /// Delay between taking a fix and the robot receiving it, s.
    pub latency: f64,
    /// How the fix is used.
    pub fusion: Fusion,
}

impl FixSpec {
    /// Refuses an empty schedule and negative or non-finite noises and latency.
    pub fn validate(&self) -> Result<(), ParamError> {
        match self.schedule {
            FixSchedule::EverySamples(n) => {
                check::at_least_one("every_steps", n)?;
            }
            FixSchedule::Period(p) => {
                check::positive("period", p)?;
            }
        }
        check::non_negative("position_noise", self.position_noise)?;
        if let Some(v) = self.heading_noise {
            check::non_negative("heading_noise", v)?;
        }
        check::non_negative("latency", self.latency)?;
        Ok(())
    }

    /// Seconds between fixes, for odometry sampled every `sample_period`
    /// seconds (`every_steps` samples of it, or the `period` itself).
    pub fn interval(&self, sample_period: f64) -> f64 {
        match self.schedule {
            FixSchedule::Period(p) => p,
            FixSchedule::EverySamples(n) => n as f64 * sample_period,
        }
    }

    /// Odometry samples between fixes, for sampling every `period` seconds.
    pub fn samples_between(&self, period: f64) -> Result<u64, ParamError> {
        match self.schedule {
            FixSchedule::EverySamples(n) => check::at_least_one("every_steps", n),
            FixSchedule::Period(p) => check::multiple_of(
                "period",
                p,
                period,
                &format!("the odometry period {period} s"),
            ),
        }
    }
}

/// One robot's odometry: sampling period, errors and fixes. Built through
/// [`OdometrySpec::new`], which checks all three.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OdometrySpec {
    period: f64,
    errors: ErrorModel,
    fixes: Option<FixSpec>,
}

impl OdometrySpec {
    /// A robot's odometry, refusing a period that is not a finite number > 0,
    /// an invalid error model or fixes ([`ErrorModel::validate`],
    /// [`FixSpec::validate`]) and fixes that are not a whole number of samples apart.
    pub fn new(
        period: f64,
        errors: ErrorModel,
        fixes: Option<FixSpec>,
    ) -> Result<OdometrySpec, ParamError> {
        let spec = OdometrySpec {
            period,
            errors,
            fixes,
        };
        spec.validate()?;
        Ok(spec)
    }

    /// Sampling period of the encoders, s (a whole multiple of the simulation step).
    #[inline]
    pub const fn period(&self) -> f64 {
        self.period
    }

    /// What makes the encoders lie.
    #[inline]
    pub const fn errors(&self) -> ErrorModel {
        self.errors
    }

    /// Absolute fixes, if any.
    #[inline]
    pub const fn fixes(&self) -> Option<FixSpec> {
        self.fixes
    }

    /// [`OdometrySpec::new`]'s checks; the samples between fixes (0: no fixes).
    fn validate(&self) -> Result<u64, ParamError> {
        check::positive("period", self.period)?;
        self.errors.validate()?;
        match &self.fixes {
            None => Ok(0),
            Some(f) => {
                f.validate()?;
                f.samples_between(self.period)
            }
        }
    }
}

/// A fix on its way to the robot.
#[derive(Debug, Clone, Copy)]
struct PendingFix {
    arrives: f64,
    fix: Pose,
    estimate_then: Pose,
}

/// A robot's odometer and estimator, run at the sampling instants.
///
/// It reads the robot's true motion — the state and `s = ∫v dt` — turns it into
/// encoder counts through the robot's actual wheels, and dead-reckons with the
/// nominal ones.
#[derive(Debug, Clone)]
pub struct Odometer {
    spec: OdometrySpec,
    fix_every: u64,
    nominal_radius: f64,
    nominal_half_wheelbase: f64,
    radii: (f64, f64),
    actual_half_wheelbase: f64,
    rng: ChaCha8Rng,
    estimate: Pose,
    /// The true pose at the last sample.
    anchor: Pose,
    fusion: FixFusion,
    origin: (f64, f64),
    wheel_angle: [f64; 2],
    wheel_travel: [f64; 2],
    ticks: [i64; 2],
    speed_noise: (f64, f64),
    samples: u64,
    fixes: u64,
    pending: VecDeque<PendingFix>,
}

impl Odometer {
    /// An odometer for `robot` starting at `start` (the start pose is known
    /// exactly), sampling every `period` seconds. `seed` and `stream` choose the
    /// random numbers (one stream per robot).
    pub fn new(
        spec: OdometrySpec,
        robot: &RobotParams,
        start: &State,
        seed: u64,
        stream: u64,
    ) -> Result<Odometer, ParamError> {
        Odometer::with_wheels(
            spec,
            robot.half_wheelbase(),
            robot.wheel_radius(),
            start,
            seed,
            stream,
        )
    }

    /// [`Odometer::new`] for any robot with half wheel separation
    /// `half_wheelbase` and wheel radius `wheel_radius` (m), e.g. a velocity
    /// base ([`crate::base::VelocityRobot`]).
    pub fn with_wheels(
        spec: OdometrySpec,
        half_wheelbase: f64,
        wheel_radius: f64,
        start: &State,
        seed: u64,
        stream: u64,
    ) -> Result<Odometer, ParamError> {
        let fix_every = spec.validate()?;
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        rng.set_stream(stream);
        let estimate = start.pose();
        // The simulator's fixes come from its own truth: none is gated.
        let fusion = FixFusion::new(spec.fixes.map_or(Fusion::Reset, |f| f.fusion), false);
        let capacity = match spec.fixes {
            Some(f) if fix_every > 0 => {
                (f.latency / (spec.period * fix_every as f64)).ceil() as usize + 2
            }
            _ => 0,
        };
        Ok(Odometer {
            spec,
            fix_every,
            nominal_radius: wheel_radius,
            nominal_half_wheelbase: half_wheelbase,
            radii: spec.errors.wheel_radii(wheel_radius),
            actual_half_wheelbase: half_wheelbase * spec.errors.wheelbase_ratio,
            rng,
            estimate,
            anchor: estimate,
            fusion,
            origin: (0.0, start.theta),
            wheel_angle: [0.0; 2],
            wheel_travel: [0.0; 2],
            ticks: [0; 2],
            speed_noise: (0.0, 0.0),
            samples: 0,
            fixes: 0,
            pending: VecDeque::with_capacity(capacity),
        })
    }

    /// The pose estimate `(x̂, ŷ, θ̂)` of the last sample.
    pub fn estimate(&self) -> Pose {
        self.estimate
    }

    /// The pose the robot believes it has now, in true state `s`: the last
    /// sample's estimate carried forward by the motion since (see [`Odometer::measure`]).
    #[inline]
    pub fn believed(&self, s: &State) -> Pose {
        self.estimate.compose(&self.anchor.between(&s.pose()))
    }

    /// The drift in true state `s`: how far the believed position
    /// ([`Odometer::believed`]) is from the true one, m.
    #[inline]
    pub fn drift(&self, s: &State) -> f64 {
        let b = self.believed(s);
        (s.x - b.x).hypot(s.y - b.y)
    }

    /// Its odometry: sampling period, error model, fixes.
    pub fn spec(&self) -> OdometrySpec {
        self.spec
    }

    /// Number of fixes applied so far.
    pub fn fixes_applied(&self) -> u64 {
        self.fixes
    }

    /// Number of samples taken so far.
    pub fn samples(&self) -> u64 {
        self.samples
    }

    /// What the controller sees of a robot in true state `s`: the estimated pose
    /// and the directly measured speeds (Assumption 2, with their noise).
    ///
    /// At a sampling instant that is the odometry estimate. Between samples (the
    /// RK4 stages of a continuous-time controller) the estimate follows the
    /// robot's motion since the last sample, its error frozen until the next one,
    /// so the controller never acts on a pose that lags by a sample.
    #[inline]
    pub fn measure(&self, s: &State) -> State {
        let pose = self.believed(s);
        State {
            x: pose.x,
            y: pose.y,
            theta: pose.theta,
            v: s.v + self.speed_noise.0,
            omega: s.omega + self.speed_noise.1,
        }
    }

    fn normal(&mut self) -> f64 {
        self.rng.sample(StandardNormal)
    }

    /// The encoders' measured wheel displacements since the last sample, given the
    /// robot's total travel `distance = ∫v dt` and heading `theta` (unwrapped).
    fn read_encoders(&mut self, distance: f64, theta: f64) -> (WheelDisplacement, [f64; 2]) {
        let turn = self.actual_half_wheelbase * (theta - self.origin.1);
        let travel = [distance + turn, distance - turn];
        let radii = [self.radii.0, self.radii.1];
        let mut measured = [0.0; 2];
        let mut true_step = [0.0; 2];
        for w in 0..2 {
            let angle = travel[w] / radii[w];
            true_step[w] = travel[w] - self.wheel_travel[w];
            measured[w] = match self.spec.errors.ticks_per_rev {
                None => (angle - self.wheel_angle[w]) * self.nominal_radius,
                Some(n) => {
                    let per_tick = std::f64::consts::TAU / f64::from(n);
                    let count = (angle / per_tick).floor() as i64;
                    let d = (count - self.ticks[w]) as f64 * per_tick * self.nominal_radius;
                    self.ticks[w] = count;
                    d
                }
            };
            self.wheel_angle[w] = angle;
            self.wheel_travel[w] = travel[w];
        }
        let slip = self.spec.errors.slip;
        if slip > 0.0 {
            for w in 0..2 {
                measured[w] += self.normal() * (slip * true_step[w].abs()).sqrt();
            }
        }
        (
            WheelDisplacement {
                right: measured[0],
                left: measured[1],
            },
            true_step,
        )
    }

    /// One sample at time `t`: the robot is now in true state `s` having travelled
    /// `distance = ∫v dt` since the start. Updates the estimate, takes and applies
    /// fixes.
    pub fn sample(&mut self, t: f64, s: &State, distance: f64) {
        let (measured, true_step) = self.read_encoders(distance, s.theta);
        let l = self.nominal_half_wheelbase;
        let (mut delta, big_theta) = measured.to_motion(l);
        let errors = self.spec.errors;
        if errors.zeta_model == ZetaModel::Wheels {
            // Eq. 24: Δ̂ = Δ − ζ with Θ̂ = Θ (the same ζ on both wheels, eq. 23).
            delta -= errors.zeta;
        }
        let previous = self.estimate;
        self.estimate = arc_update(&previous, delta, big_theta);
        if errors.zeta_model == ZetaModel::WorstCase {
            // Eq. 31: the truth runs ahead of the estimate by ζ on both axes.
            self.estimate.x -= errors.zeta;
            self.estimate.y -= errors.zeta;
        }
        if let Some(ekf) = self.fusion.ekf_mut() {
            let var = errors.wheel_variance(self.nominal_radius, true_step);
            ekf.predict(&previous, delta, big_theta, l, var);
        }
        if errors.speed_noise > 0.0 || errors.turn_rate_noise > 0.0 {
            self.speed_noise = (
                self.normal() * errors.speed_noise,
                self.normal() * errors.turn_rate_noise,
            );
        }
        self.samples += 1;
        self.anchor = s.pose();
        if let Some(f) = self.spec.fixes {
            if self.samples.is_multiple_of(self.fix_every) {
                let mut fix = Pose {
                    x: s.x + self.normal() * f.position_noise,
                    y: s.y + self.normal() * f.position_noise,
                    theta: self.estimate.theta,
                };
                if let Some(sd) = f.heading_noise {
                    fix.theta = s.theta + self.normal() * sd;
                }
                self.pending.push_back(PendingFix {
                    arrives: t + f.latency,
                    fix,
                    estimate_then: self.estimate,
                });
            }
            // Half a sample of slack: arrival times are sums of floats.
            while let Some(p) = self.pending.front().copied() {
                if p.arrives > t + 0.5 * self.spec.period {
                    break;
                }
                self.pending.pop_front();
                self.apply(&p, &f);
            }
        }
    }

    fn apply(&mut self, p: &PendingFix, f: &FixSpec) {
        let noise = FixNoise {
            position: f.position_noise,
            heading: f.heading_noise,
        };
        // Never gated (see `Odometer::with_wheels`).
        if let Ok(estimate) = self
            .fusion
            .apply(&self.estimate, &p.estimate_then, &p.fix, noise)
        {
            self.estimate = estimate;
            self.fixes += 1;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        /// `arc_motion` inverts `arc_update` for any arc (forward or
        /// backward, straight or turning, from any pose): the same `(Δ, Θ)`
        /// back, and the same pose reached again.
        #[test]
        fn arc_motion_inverts_arc_update(
            x in -50.0..50.0f64, y in -50.0..50.0f64, theta in -20.0..20.0f64,
            delta in -2.0..2.0f64, big_theta in -3.0..3.0f64
        ) {
            let from = Pose { x, y, theta };
            let to = arc_update(&from, delta, big_theta);
            let (d, b) = arc_motion(&from, &to);
            prop_assert!((b - big_theta).abs() < 1e-12);
            prop_assert!((d - delta).abs() < 1e-9 * (1.0 + delta.abs()), "{d} vs {delta}");
            let again = arc_update(&from, d, b);
            prop_assert!((again.x - to.x).abs() < 1e-9 && (again.y - to.y).abs() < 1e-9);
        }
    }

    #[test]
    fn straight_and_turn_in_place() {
        let p = Pose::default();
        let q = dead_reckon(
            &p,
            WheelDisplacement {
                right: 1.0,
                left: 1.0,
            },
            0.2,
        );
        assert_eq!((q.x, q.y, q.theta), (1.0, 0.0, 0.0));
        let q = dead_reckon(
            &p,
            WheelDisplacement {
                right: 0.1,
                left: -0.1,
            },
            0.2,
        );
        assert!(q.x.abs() < 1e-15 && q.y.abs() < 1e-15 && (q.theta - 0.5).abs() < 1e-15);
    }

    #[test]
    fn arc_update_is_eq_22() {
        let p = Pose {
            x: 1.0,
            y: -2.0,
            theta: 0.7,
        };
        let (delta, th) = (0.3, 0.2);
        let q = arc_update(&p, delta, th);
        let r = delta / th;
        assert!((q.x - (p.x + r * ((0.7f64 + th).sin() - 0.7f64.sin()))).abs() < 1e-15);
        assert!((q.y - (p.y - r * ((0.7f64 + th).cos() - 0.7f64.cos()))).abs() < 1e-15);
    }

    #[test]
    fn wheel_radii_keep_the_mean_and_the_ratio() {
        let e = ErrorModel {
            wheel_diameter_ratio: 1.02,
            ..ErrorModel::PERFECT
        };
        let (r, l) = e.wheel_radii(0.1);
        assert!((r / l - 1.02).abs() < 1e-15 && (0.5 * (r + l) - 0.1).abs() < 1e-15);
    }

    #[test]
    fn invalid_error_models_are_refused() {
        let bad = ErrorModel {
            wheelbase_ratio: 0.0,
            ..ErrorModel::PERFECT
        };
        assert_eq!(bad.validate().unwrap_err().field, "wheelbase_ratio");
        let bad = ErrorModel {
            slip: -1.0,
            ..ErrorModel::PERFECT
        };
        assert_eq!(bad.validate().unwrap_err().field, "slip");
        let bad = ErrorModel {
            zeta: f64::NAN,
            ..ErrorModel::PERFECT
        };
        assert_eq!(bad.validate().unwrap_err().field, "zeta");
    }
}
