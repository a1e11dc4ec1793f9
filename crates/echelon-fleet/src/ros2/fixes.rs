//! Absolute fixes from ROS 2 for a fleet robot (paper section 6): poses
//! from a motion-capture driver (`geometry_msgs/PoseStamped`) or a
//! localiser (`geometry_msgs/PoseWithCovarianceStamped`, AMCL's
//! `amcl_pose`) fused with the robot's odometry, and Theorem 2 in the loop.
//!
//! [`FixInput`] is sans-IO, fed by [`super::drive::Ros2Drive`]: the raw
//! odometry samples with their stamps ([`FixInput::on_odom`]) and the fix
//! messages ([`FixInput::on_fix`]). It keeps the *correction*, the pose of
//! the robot's odom frame in the world as the fixes say it is (at first the
//! link's `odom_origin`); the robot's world estimate is `correction ⊕ raw
//! odometry`. A fix goes through the simulator's own fusion
//! ([`echelon::odometry::fuse::FixFusion`], `reset` or `ekf`, one
//! implementation):
//!
//! 1. checked (type and hash on the key, CDR, finite, its `frame_id`, a
//!    usable orientation: a unit quaternion within tf2's tolerance, the
//!    drive's rule for odometry,
//!    [`echelon_ros2::msgs::Quaternion::checked_yaw`]), else counted and
//!    refused;
//! 2. mapped into the world (`frame_origin ⊕ pose`);
//! 3. latency compensated from its stamp: the raw odometry at the stamp is
//!    interpolated in the recent history (odometry stamps and fix stamps
//!    must share a clock: chrony), and the fix carried to now by the motion
//!    the odometry measured since (`fix ⊕ (then⁻¹ ⊕ now)`);
//! 4. bounded: a fix that would put the robot farther from the world origin
//!    than the divergence guard's position bound (`[sim] bounds`,
//!    [`Bounds::distance`]) is refused and counted
//!    ([`FixRefusal::BeyondBounds`]), first fix or not, gate or not: taken,
//!    it would stop the robot as diverged on one message (a finite fix
//!    1e300 m away did);
//! 5. gated: its squared Mahalanobis distance from the estimate, with the
//!    covariance the odometry's error model grew since the last fix, beyond
//!    the chi-square 99.9 % quantile, is refused and counted. The first fix
//!    is not gated: until then the world pose is only `odom_origin`'s
//!    say-so, which states no uncertainty (the covariance the odometry grew
//!    since is its drift from `odom_origin`, not how wrong `odom_origin`
//!    may be), and a robot switched on elsewhere than its `odom_origin`
//!    says must take a genuine first fix metres away (relocalisation). After
//!    [`RELOCALIZE_AFTER`] refusals in a row the fixes are believed over
//!    the odometry (the robot relocalises: counted and said);
//! 6. fused: the covariance is the message's when it has one
//!    (`PoseWithCovarianceStamped`), else the scenario's `position_noise`
//!    and `heading_noise` (no `heading_noise`: the heading is not fixed).
//!
//! Fixes missing for longer than the timeout are reported once per outage
//! and the robot carries on on odometry alone. With a `tolerance`, the fix
//! interval Theorem 2 requires for the kinematic law
//! ([`echelon::odometry::bound::KinematicTheorem2`]: `‖e‖ ≤ √2 N ζ / γ`) is
//! computed from the odometry error model ([`ErrorModel::zeta_per_sample`]
//! at the base's top speed), and fixes that come slower are warned about
//! once, saying by how much.

use std::collections::VecDeque;

use echelon::agent::AgentSpec;
use echelon::guard::Bounds;
use echelon::model::{Pose, wrap_angle};
use echelon::odometry::fuse::{FixFusion, FixNoise, carry};
use echelon::odometry::{ErrorModel, FixSpec, arc_motion};
use echelon::plan::Plan;
use echelon::scenario::schema::FixMessage;
use echelon::scenario::{FixSource, Ros2Link};
use echelon_ros2::KeyScheme;
use echelon_ros2::keys::check_topic_key;
use echelon_ros2::msgs::{
    MessageType, POSE_STAMPED, POSE_WITH_COVARIANCE_STAMPED, PoseStamped,
    PoseWithCovarianceStamped, RosMessage,
};

use super::refusal::SampleRefusal;

mod report;
use crate::FleetError;
pub use report::{FixCounters, FixReport, FixRequirement, GAMMA};

/// Raw odometry samples kept for latency compensation (20 s at 50 Hz).
pub const HISTORY: usize = 1024;
/// Refused fixes in a row after which the fixes are believed over the
/// odometry.
pub const RELOCALIZE_AFTER: u32 = 10;
/// The default timeout, in fix periods.
pub const TIMEOUT_PERIODS: f64 = 3.0;

/// The message type of a fix source.
pub fn fix_type(message: FixMessage) -> &'static MessageType {
    match message {
        FixMessage::PoseStamped => &POSE_STAMPED,
        FixMessage::PoseWithCovarianceStamped => &POSE_WITH_COVARIANCE_STAMPED,
    }
}

/// Why a fix was refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum FixRefusal {
    /// The sample itself (type, CDR, finiteness, frame).
    #[error(transparent)]
    Sample(#[from] SampleRefusal),
    /// Another `frame_id` than configured.
    #[error("frame `{0}`, expected `{1}`")]
    Frame(String, String),
    /// It would put the robot beyond the divergence guard's position
    /// bound: `distance` m from the world origin, the bound `bound` m.
    #[error(
        "beyond the bounds: {distance:.3e} m from the world origin, the guard's bound {bound} m"
    )]
    BeyondBounds {
        /// The distance of the pose it gives, m.
        distance: f64,
        /// `[sim] bounds` distance, m.
        bound: f64,
    },
    /// No odometry at its stamp.
    #[error("no odometry at the fix's stamp")]
    Unmatched,
    /// Implausibly far from the estimate.
    #[error("gated: squared Mahalanobis distance {distance_sq:.1} > {threshold:.1}")]
    Gated {
        /// `νᵀ S⁻¹ ν`.
        distance_sq: f64,
        /// The threshold.
        threshold: f64,
    },
}

/// How a robot's odometry errs and how it is sampled: what grows the
/// estimate's covariance between fixes and gives Theorem 2 its `ζ`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OdometryModel {
    /// The error model (the agent's `[odometry]`; perfect without one).
    pub errors: ErrorModel,
    /// `(l, r)`: half wheelbase and wheel radius, m.
    pub wheels: (f64, f64),
    /// The odometry sample period `T_s`, s.
    pub sample_period: f64,
    /// The base's top speed, m/s.
    pub top_speed: f64,
}

/// One robot's fixes from ROS 2 (see the module doc).
#[derive(Debug, Clone)]
pub struct FixInput {
    agent: u32,
    source: FixSource,
    key_scheme: KeyScheme,
    /// The scenario's fix noise (`PoseStamped`; the fallback of a
    /// covariance with zeros).
    noise: FixNoise,
    fusion: FixFusion,
    model: OdometryModel,
    /// The divergence guard's bounds (`[sim] bounds`): no fix may put the
    /// robot beyond its position bound.
    bounds: Bounds,
    timeout: f64,
    required: Option<FixRequirement>,
    /// The odom frame's pose in the world.
    correction: Pose,
    /// Recent raw odometry: (stamp ns, pose in the odom frame).
    history: VecDeque<(i64, Pose)>,
    /// Fleet time odometry began (the first sample).
    began: Option<f64>,
    last_fix: Option<f64>,
    /// The noise of the last applied fix.
    last_noise: Option<FixNoise>,
    intervals: (u64, f64, f64),
    zeta_measured: Option<f64>,
    refused_in_a_row: u32,
    outage: bool,
    too_slow: bool,
    counters: FixCounters,
}

impl FixInput {
    /// Fixes for agent `agent` from `source` (keys in `key_scheme`), of
    /// the agent's fix spec `spec` (noise, fusion, nominal schedule), on
    /// odometry that errs as `model`, starting from the odom frame at
    /// `odom_origin`; Theorem 2 with gain `ke`.
    pub fn new(
        agent: u32,
        source: FixSource,
        key_scheme: KeyScheme,
        spec: &FixSpec,
        model: OdometryModel,
        odom_origin: Pose,
        ke: f64,
    ) -> Result<FixInput, String> {
        let period = spec.interval(model.sample_period);
        let required = match source.tolerance {
            Some(tolerance) => {
                let step = model.top_speed * model.sample_period;
                let zeta = model.errors.zeta_per_sample(model.wheels.1, step);
                FixRequirement::new(ke, zeta, model.sample_period, tolerance)?
            }
            None => None,
        };
        Ok(FixInput {
            agent,
            timeout: source.timeout.unwrap_or(TIMEOUT_PERIODS * period),
            fusion: FixFusion::new(spec.fusion(), source.gate),
            source,
            key_scheme,
            noise: FixNoise {
                position: spec.position_noise(),
                heading: spec.heading_noise(),
            },
            model,
            bounds: Bounds::DEFAULT,
            required,
            correction: odom_origin,
            history: VecDeque::with_capacity(HISTORY),
            began: None,
            last_fix: None,
            last_noise: None,
            intervals: (0, 0.0, 0.0),
            zeta_measured: None,
            refused_in_a_row: 0,
            outage: false,
            too_slow: false,
            counters: FixCounters::default(),
        })
    }

    /// The same fixes within the divergence guard's `bounds` (the robot's
    /// `[sim] bounds`; without: [`Bounds::DEFAULT`]): a fix that would put
    /// the robot farther from the world origin than `bounds.distance` is
    /// refused ([`FixRefusal::BeyondBounds`]).
    pub fn with_bounds(self, bounds: Bounds) -> Self {
        FixInput { bounds, ..self }
    }

    /// The source.
    pub fn source(&self) -> &FixSource {
        &self.source
    }

    /// The pose of the robot's odom frame in the world, as the fixes say.
    pub fn correction(&self) -> Pose {
        self.correction
    }

    /// What it counted.
    pub fn counters(&self) -> &FixCounters {
        &self.counters
    }

    /// The estimate's covariance of `(x, y, θ)`, when it keeps one (`ekf`,
    /// or a gate).
    pub fn covariance(&self) -> Option<[[f64; 3]; 3]> {
        self.fusion.covariance()
    }

    /// Fleet time of the last applied fix and its noise (`None`: none yet).
    pub fn last_fix(&self) -> Option<(f64, FixNoise)> {
        self.last_fix.zip(self.last_noise)
    }

    /// Its report at fleet time `t`.
    pub fn report(&self, t: f64) -> FixReport {
        let (n, sum, max) = self.intervals;
        FixReport {
            counters: self.counters,
            interval_max: (n > 0).then_some(max),
            interval_mean: (n > 0).then(|| sum / n as f64),
            age: self.last_fix.or(self.began).map(|at| t - at),
            zeta_measured: self.zeta_measured,
            required: self.required,
            too_slow: self.too_slow,
        }
    }

    /// A raw odometry sample (odom frame) stamped `stamp_ns`, arrived at
    /// fleet time `t`: grows the covariance by the model and keeps it for
    /// latency compensation.
    pub fn on_odom(&mut self, stamp_ns: i64, raw: Pose, t: f64) {
        self.began.get_or_insert(t);
        match self.history.back().copied() {
            // The robot's clock went back (it restarted): a new history.
            Some((last, _)) if stamp_ns < last => self.history.clear(),
            Some((_, prev)) => {
                if let Some(ekf) = self.fusion.ekf_mut() {
                    let (delta, big_theta) = arc_motion(&prev, &raw);
                    let (l, r) = self.model.wheels;
                    let step = [delta + l * big_theta, delta - l * big_theta];
                    let var = self.model.errors.wheel_variance(r, step);
                    ekf.predict(&self.correction.compose(&prev), delta, big_theta, l, var);
                }
            }
            None => {}
        }
        if self.history.len() == HISTORY {
            self.history.pop_front();
        }
        self.history.push_back((stamp_ns, raw));
    }

    /// Fleet time `t`: reports (once per outage) fixes missing for longer
    /// than the timeout.
    pub fn tick(&mut self, t: f64) {
        let Some(since) = self.last_fix.or(self.began) else {
            return;
        };
        if !self.outage && t - since > self.timeout {
            self.outage = true;
            self.counters.outages += 1;
            eprintln!(
                "agent {}: no fix from {} for {:.2} s (timeout {} s): carrying on on odometry alone",
                self.agent,
                self.source.topic,
                t - since,
                self.timeout
            );
        }
    }

    /// A fix message on `key` that arrived at fleet time `t`: checked,
    /// carried to now, gated and fused, or counted and refused.
    pub fn on_fix(&mut self, key: &str, payload: &[u8], t: f64) -> Result<(), FixRefusal> {
        self.counters.received += 1;
        let result = self.take(key, payload, t);
        if let Err(e) = &result {
            let c = &mut self.counters;
            match e {
                FixRefusal::Sample(SampleRefusal::WrongType(_)) => c.wrong_type += 1,
                FixRefusal::Sample(SampleRefusal::NonFinite(_)) => c.non_finite += 1,
                FixRefusal::Frame(..) => c.wrong_frame += 1,
                FixRefusal::Sample(_) => c.malformed += 1,
                FixRefusal::Unmatched => c.unmatched += 1,
                FixRefusal::BeyondBounds { .. } => c.beyond_bounds += 1,
                FixRefusal::Gated { .. } => c.gated += 1,
            }
        }
        result
    }

    fn take(&mut self, key: &str, payload: &[u8], t: f64) -> Result<(), FixRefusal> {
        let (fix, stamp, noise) = self.decode(key, payload)?;
        let (&(_, raw_now), raw_then) = match (self.history.back(), self.raw_at(stamp)) {
            (Some(now), Some(then)) => (now, then),
            _ => return Err(FixRefusal::Unmatched),
        };
        let estimate = self.correction.compose(&raw_now);
        let then = self.correction.compose(&raw_then);
        let mut fix = self.source.frame_origin.compose(&fix);
        // The heading continuous with the estimate's (which is unwrapped).
        fix.theta = then.theta + wrap_angle(fix.theta - then.theta);
        let carried = carry(&fix, &then, &estimate);
        // The position the fix gives the robot now (what `reset` makes the
        // estimate; `ekf` moves it towards it), checked before the fusion
        // counts or changes anything.
        let distance = carried.x.hypot(carried.y);
        // (A fix near f64::MAX overflows to ∞ or NaN on the way: beyond too.)
        if !distance.is_finite() || distance > self.bounds.distance {
            return Err(FixRefusal::BeyondBounds {
                distance,
                bound: self.bounds.distance,
            });
        }
        let fused = if self.last_fix.is_none() {
            // Until its first fix the world pose is only `odom_origin`'s
            // say-so, with no stated uncertainty: the first fix within the
            // bounds is taken as it is (a robot switched on elsewhere than
            // its `odom_origin` relocalises on it).
            Ok(self.fusion.reset(&estimate, &then, &fix, noise))
        } else {
            self.fusion.apply(&estimate, &then, &fix, noise)
        };
        let new = match fused {
            Ok(new) => {
                self.refused_in_a_row = 0;
                new
            }
            Err(g) => {
                self.refused_in_a_row += 1;
                if self.refused_in_a_row < RELOCALIZE_AFTER {
                    return Err(FixRefusal::Gated {
                        distance_sq: g.distance_sq,
                        threshold: g.threshold,
                    });
                }
                // The fixes agree with one another against the odometry:
                // believe them.
                self.counters.gated += 1;
                self.counters.relocalized += 1;
                self.refused_in_a_row = 0;
                eprintln!(
                    "agent {}: {} fixes in a row refused by the gate; relocalised on {} ({:.3} m from the odometry estimate)",
                    self.agent,
                    RELOCALIZE_AFTER,
                    self.source.topic,
                    (carried.x - estimate.x).hypot(carried.y - estimate.y)
                );
                self.fusion.reset(&estimate, &then, &fix, noise)
            }
        };
        self.applied(t, &estimate, &carried);
        self.last_noise = Some(noise);
        // new = correction' ⊕ raw_now.
        self.correction = new.compose(&raw_now.between(&Pose::default()));
        Ok(())
    }

    /// Bookkeeping of a fix applied at fleet time `t` whose carried pose
    /// was `carried` against the odometry estimate `estimate`.
    fn applied(&mut self, t: f64, estimate: &Pose, carried: &Pose) {
        self.counters.applied += 1;
        if let Some(last) = self.last_fix {
            let interval = t - last;
            let (n, sum, max) = self.intervals;
            self.intervals = (n + 1, sum + interval, max.max(interval));
            let samples = (interval / self.model.sample_period).max(1.0);
            let error = (carried.x - estimate.x)
                .abs()
                .max((carried.y - estimate.y).abs());
            let zeta = error / samples;
            self.zeta_measured = Some(self.zeta_measured.map_or(zeta, |z| z.max(zeta)));
            if let Some(req) = self.required
                && interval > req.interval
                && !self.too_slow
            {
                self.too_slow = true;
                eprintln!(
                    "agent {}: fixes from {} came {:.3} s apart; Theorem 2 requires at most {:.3} s for ‖e‖ ≤ {} m (ζ = {:.3e} m per {} s sample): {:.1}× too slow",
                    self.agent,
                    self.source.topic,
                    interval,
                    req.interval,
                    req.tolerance,
                    req.zeta,
                    req.sample_period,
                    interval / req.interval
                );
            }
        }
        if self.outage {
            self.outage = false;
            eprintln!(
                "agent {}: fixes from {} again",
                self.agent, self.source.topic
            );
        }
        self.last_fix = Some(t);
    }

    /// The fix in its frame, its stamp (ns) and its noise.
    fn decode(&self, key: &str, payload: &[u8]) -> Result<(Pose, i64, FixNoise), FixRefusal> {
        let ty = fix_type(self.source.message);
        check_topic_key(self.key_scheme, key, ty)
            .map_err(|e| SampleRefusal::WrongType(e.to_string()))?;
        let (header, pose, covariance) = match self.source.message {
            FixMessage::PoseStamped => {
                let m = PoseStamped::from_cdr_finite(payload).map_err(SampleRefusal::from)?;
                (m.header, m.pose, None)
            }
            FixMessage::PoseWithCovarianceStamped => {
                let m = PoseWithCovarianceStamped::from_cdr_finite(payload)
                    .map_err(SampleRefusal::from)?;
                let c = m.planar_covariance();
                (m.header, m.pose.pose, Some(c))
            }
        };
        if header.frame_id != self.source.frame {
            return Err(FixRefusal::Frame(
                header.frame_id,
                self.source.frame.clone(),
            ));
        }
        let fix = Pose {
            x: pose.position.x,
            y: pose.position.y,
            theta: pose
                .orientation
                .checked_yaw()
                .ok_or(SampleRefusal::Orientation)?,
        };
        let noise = match covariance {
            None => self.noise,
            Some(c) => {
                let position = c[0][0].max(c[1][1]);
                let heading = c[2][2];
                FixNoise {
                    position: if position > 0.0 {
                        position.sqrt()
                    } else {
                        self.noise.position
                    },
                    heading: if heading > 0.0 {
                        Some(heading.sqrt())
                    } else {
                        self.noise.heading
                    },
                }
            }
        };
        Ok((fix, header.stamp.to_nanos(), noise))
    }

    /// The raw odometry at `stamp` ns, interpolated; the latest for a zero
    /// stamp (unstamped) or one after it; `None` before the history.
    fn raw_at(&self, stamp: i64) -> Option<Pose> {
        let &(last_stamp, last) = self.history.back()?;
        if stamp == 0 || stamp >= last_stamp {
            return Some(last);
        }
        let i = self.history.partition_point(|&(s, _)| s <= stamp);
        if i == 0 {
            return None;
        }
        let (s0, p0) = self.history[i - 1];
        let (s1, p1) = self.history[i];
        let w = (stamp - s0) as f64 / (s1 - s0) as f64;
        Some(Pose {
            x: p0.x + w * (p1.x - p0.x),
            y: p0.y + w * (p1.y - p0.y),
            theta: p0.theta + w * (p1.theta - p0.theta),
        })
    }
}

/// Agent `agent`'s fixes from ROS 2 as the scenario describes them (its
/// link's `fixes` source, its fix spec and odometry error model from
/// `plan`, its velocity base's top speed and its gain `K_e` from `spec`);
/// `None` when it takes none.
pub fn for_agent(
    agent: u32,
    link: &Ros2Link,
    plan: &Plan,
    spec: &AgentSpec,
) -> Result<Option<FixInput>, FleetError> {
    let Some(source) = link.fixes.clone() else {
        return Ok(None);
    };
    let refuse = |why: String| FleetError::Config(format!("agent {agent}: fixes: {why}"));
    let odometer = plan.odometer(agent as usize - 1);
    let Some((odometry, fixes)) = odometer.and_then(|o| Some((o.spec(), o.spec().fixes()?))) else {
        return Err(refuse(
            "`source` names a topic but the agent takes no fixes (its odometry is disabled?)"
                .into(),
        ));
    };
    let top_speed = spec
        .velocity_robot()
        .map_or(f64::INFINITY, |r| r.base().v_max());
    if source.tolerance.is_some() && !top_speed.is_finite() && odometry.errors().slip() > 0.0 {
        return Err(refuse(
            "`tolerance` with slip needs the base's top speed (`v_max`) to bound the odometry error per sample".into(),
        ));
    }
    let model = OdometryModel {
        errors: odometry.errors(),
        wheels: spec.drive().wheels(),
        sample_period: odometry.period(),
        top_speed,
    };
    FixInput::new(
        agent,
        source,
        link.key_scheme,
        &fixes,
        model,
        link.odom_origin,
        spec.gains().ke(),
    )
    .map(|f| Some(f.with_bounds(plan.config().bounds)))
    .map_err(refuse)
}

#[cfg(test)]
mod tests;
