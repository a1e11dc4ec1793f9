//! The odometer: encoders read through the robot's actual wheels, dead
//! reckoning with the nominal ones, and fixes applied as they arrive.

use std::collections::VecDeque;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;

use super::fuse::{FixFusion, FixNoise};
use super::{FixSpec, Fusion, OdometrySpec, WheelDisplacement, ZetaModel, arc_update};
use crate::model::{Pose, RobotParams, State};

/// Most fixes in flight an odometer makes room for when it is built
/// ([`Odometer::with_wheels`]): 2¹⁶, a minute of latency at a fix every
/// millisecond. A longer latency's queue grows while the run fills it.
const MAX_PREALLOCATED_FIXES: usize = 1 << 16;

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
    ) -> Odometer {
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
    /// base ([`crate::model::base::VelocityRobot`]).
    pub fn with_wheels(
        spec: OdometrySpec,
        half_wheelbase: f64,
        wheel_radius: f64,
        start: &State,
        seed: u64,
        stream: u64,
    ) -> Odometer {
        let fix_every = spec.fix_every;
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        rng.set_stream(stream);
        let estimate = start.pose();
        // The simulator's fixes come from its own truth: none is gated.
        let fusion = FixFusion::new(spec.fixes.map_or(Fusion::Reset, |f| f.fusion()), false);
        // Room for the fixes in flight (a latency's worth), so that the run
        // does not allocate; at most `MAX_PREALLOCATED_FIXES` up front, as the
        // latency is any finite number here (beyond, the queue grows).
        let capacity = match spec.fixes {
            Some(f) if fix_every > 0 => {
                let in_flight = (f.latency() / (spec.period * fix_every as f64)).ceil() + 2.0;
                in_flight.min(MAX_PREALLOCATED_FIXES as f64) as usize
            }
            _ => 0,
        };
        Odometer {
            spec,
            fix_every,
            nominal_radius: wheel_radius,
            nominal_half_wheelbase: half_wheelbase,
            radii: spec.errors.wheel_radii(wheel_radius),
            actual_half_wheelbase: half_wheelbase * spec.errors.wheelbase_ratio(),
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
        }
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
            measured[w] = match self.spec.errors.ticks_per_rev() {
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
        let slip = self.spec.errors.slip();
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
        if errors.zeta_model() == ZetaModel::Wheels {
            // Eq. 24: Δ̂ = Δ − ζ with Θ̂ = Θ (the same ζ on both wheels, eq. 23).
            delta -= errors.zeta();
        }
        let previous = self.estimate;
        self.estimate = arc_update(&previous, delta, big_theta);
        if errors.zeta_model() == ZetaModel::WorstCase {
            // Eq. 31: the truth runs ahead of the estimate by ζ on both axes.
            self.estimate.x -= errors.zeta();
            self.estimate.y -= errors.zeta();
        }
        if let Some(ekf) = self.fusion.ekf_mut() {
            let var = errors.wheel_variance(self.nominal_radius, true_step);
            ekf.predict(&previous, delta, big_theta, l, var);
        }
        if errors.speed_noise() > 0.0 || errors.turn_rate_noise() > 0.0 {
            self.speed_noise = (
                self.normal() * errors.speed_noise(),
                self.normal() * errors.turn_rate_noise(),
            );
        }
        self.samples += 1;
        self.anchor = s.pose();
        if let Some(f) = self.spec.fixes {
            if self.samples.is_multiple_of(self.fix_every) {
                let mut fix = Pose {
                    x: s.x + self.normal() * f.position_noise(),
                    y: s.y + self.normal() * f.position_noise(),
                    theta: self.estimate.theta,
                };
                if let Some(sd) = f.heading_noise() {
                    fix.theta = s.theta + self.normal() * sd;
                }
                self.pending.push_back(PendingFix {
                    arrives: t + f.latency(),
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
            position: f.position_noise(),
            heading: f.heading_noise(),
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
