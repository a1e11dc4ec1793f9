//! A velocity-controlled base: a differential-drive robot that takes a
//! velocity command `(v, ω)` and runs its own motor loops, as almost every
//! robot people own does (TurtleBot 3/4, Clearpath Jackal, any base under
//! ros2_control's `diff_drive_controller`).
//!
//! The base is modelled as the unicycle kinematics (eq. 1) driven through a
//! first-order lag per axis, with limits on speed and acceleration:
//!
//! ```text
//! ẋ = v cos θ     ẏ = v sin θ     θ̇ = ω
//! (v_c, ω_c) = limit(command)                       speed limits, curvature kept
//! v̇ = (v_c − v) / τ_v      ω̇ = (ω_c − ω) / τ_ω      then acceleration limits
//! ```
//!
//! - **Speed limits** (`v_max`, `ω_max`, like `diff_drive_controller`'s
//!   `linear.x.max_velocity` and `angular.z.max_velocity`): [`VelocityBase::limit`]
//!   scales `v` and `ω` *together* by the one factor that brings both within
//!   their limits, so the commanded curvature `ω/v` (the path) is kept; only the
//!   speed along it drops. `diff_drive_controller` clamps each axis on its own,
//!   which bends the path when one axis saturates.
//! - **Acceleration limits** (`a_max`, `α_max`, like `max_acceleration`): on the
//!   lag's response, [`AccelLimit::Joint`] (the default) scales `(v̇, ω̇)`
//!   together, so that a base starting on the command's ray (from rest, say)
//!   moves along it and keeps the curvature during the transient too;
//!   [`AccelLimit::PerAxis`] clamps each axis as `diff_drive_controller`'s
//!   `SpeedLimiter` does (its `limit_acceleration` clamps `v − v₀` to
//!   `[min_acceleration, max_acceleration]·dt` per axis), which turns a
//!   start from rest into a spin first when `ω` reaches its target sooner.
//!   Speed limiting comes first: the lag then moves each velocity monotonically
//!   towards a target inside the limits, so the actual velocity never leaves the
//!   box `|v| ≤ v_max, |ω| ≤ ω_max` it started in; and a lagged velocity never
//!   accelerates faster than its limit.
//! - **Lags of 0 give an ideal base**: that axis's velocity is algebraic, equal
//!   to the (limited) command at every instant. The kinematics then use the
//!   command directly ([`VelocityBase::derivative`] gives `v̇ = 0` for that axis,
//!   and [`VelocityBase::settle`] writes the command into the state after each
//!   step). An axis without lag cannot have an acceleration limit (there is no
//!   acceleration to limit; a rate limit is a lag): [`VelocityBase::new`]
//!   refuses a finite `a_max` with `τ_v = 0` and likewise for `ω`.
//!
//! Integration: classical RK4 with the command held or re-evaluated per stage,
//! like the torque plant ([`crate::model::RobotParams::rk4_step`]). A lag needs
//! `dt ≤ τ` to be resolved (RK4 on a lag stays monotone, no overshoot, up to
//! `dt ≈ 2.7 τ` and is unstable beyond): [`VelocityBase::check_step`].

use crate::error::ParamError;
use crate::model::State;

/// A velocity command to a base (a ROS `Twist`'s `linear.x`, `angular.z`).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct VelocityCommand {
    /// Linear speed `v`, m/s.
    pub v: f64,
    /// Angular speed `ω`, rad/s.
    pub omega: f64,
}

/// How the acceleration limits act on the two axes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(
    feature = "serde",
    derive(serde::Serialize, serde::Deserialize, schemars::JsonSchema)
)]
#[cfg_attr(feature = "serde", serde(rename_all = "kebab-case"))]
pub enum AccelLimit {
    /// `(v̇, ω̇)` scaled together by the one factor that brings both within
    /// their limits: the velocity moves in the direction the lags ask for, so
    /// the path is kept during transients that start on the command's ray.
    #[default]
    Joint,
    /// Each axis clamped on its own, as `diff_drive_controller`'s
    /// `SpeedLimiter` does.
    PerAxis,
}

/// A velocity-controlled base's lags and limits as written: unchecked.
/// [`VelocityBase::new`] checks them.
///
/// Start from a preset's (`VelocityBase::JACKAL.spec()`) or the ideal base's
/// to change a few: `VelocityBaseSpec { v_max: 0.5, ..VelocityBase::IDEAL.spec() }`.
/// The serialised form of a [`VelocityBase`] has these fields.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct VelocityBaseSpec {
    /// Lag of the linear speed `τ_v`, s: finite and `≥ 0` (0: ideal, `v`
    /// follows the command).
    pub tau_v: f64,
    /// Lag of the angular speed `τ_ω`, s: finite and `≥ 0` (0: ideal).
    pub tau_omega: f64,
    /// Largest `|v|`, m/s: `> 0` (infinite: unlimited).
    pub v_max: f64,
    /// Largest `|ω|`, rad/s: `> 0` (infinite: unlimited).
    pub omega_max: f64,
    /// Largest `|v̇|`, m/s²: `> 0`, finite only with `τ_v > 0`.
    pub a_max: f64,
    /// Largest `|ω̇|`, rad/s²: `> 0`, finite only with `τ_ω > 0`.
    pub alpha_max: f64,
    /// Joint (path-keeping) or per-axis acceleration limits.
    pub accel: AccelLimit,
}

/// A velocity-controlled base: first-order lags and limits on speed and
/// acceleration (see the [module docs](self)).
///
/// An unlimited speed or acceleration is `f64::INFINITY`. There is no
/// `Default`: [`VelocityBase::IDEAL`] is the base the kinematic law's theory
/// assumes, not a robot; the presets are real ones.
///
/// Built through [`VelocityBase::new`] (or a preset), which checks every
/// parameter (and so does deserialising), so a `VelocityBase` in hand is
/// always a possible one.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(
    feature = "serde",
    serde(try_from = "VelocityBaseSpec", into = "VelocityBaseSpec")
)]
pub struct VelocityBase {
    spec: VelocityBaseSpec,
}

impl From<VelocityBase> for VelocityBaseSpec {
    fn from(b: VelocityBase) -> VelocityBaseSpec {
        b.spec
    }
}

impl TryFrom<VelocityBaseSpec> for VelocityBase {
    type Error = ParamError;

    fn try_from(spec: VelocityBaseSpec) -> Result<Self, ParamError> {
        VelocityBase::new(spec)
    }
}

/// Checks every parameter: lags finite and `≥ 0`; limits `> 0` (infinite:
/// unlimited, NaN refused); no finite acceleration limit on an axis without
/// lag.
fn check(b: &VelocityBaseSpec) -> Result<(), ParamError> {
    for (field, tau) in [("tau_v", b.tau_v), ("tau_omega", b.tau_omega)] {
        if !tau.is_finite() {
            return Err(ParamError::new(field, tau, "must be a finite number"));
        }
        if tau < 0.0 {
            return Err(ParamError::new(
                field,
                tau,
                "must be ≥ 0 (a lag in seconds; 0 is an ideal base)",
            ));
        }
    }
    for (field, max) in [
        ("v_max", b.v_max),
        ("omega_max", b.omega_max),
        ("a_max", b.a_max),
        ("alpha_max", b.alpha_max),
    ] {
        if max.is_nan() || max <= 0.0 {
            return Err(ParamError::new(
                field,
                max,
                "must be > 0 (leave it out for no limit)",
            ));
        }
    }
    if b.tau_v == 0.0 && b.a_max.is_finite() {
        return Err(ParamError::new(
            "a_max",
            b.a_max,
            "needs tau_v > 0: a base that follows its speed command instantly has no acceleration to limit",
        ));
    }
    if b.tau_omega == 0.0 && b.alpha_max.is_finite() {
        return Err(ParamError::new(
            "alpha_max",
            b.alpha_max,
            "needs tau_omega > 0: a base that follows its turn-rate command instantly has no acceleration to limit",
        ));
    }
    Ok(())
}

impl VelocityBase {
    /// The ideal base: no lag, no limits; `v`, `ω` equal the command. With it
    /// the kinematic law gives `V̇₁ = −K_e‖e‖²` exactly (control-law.md).
    pub const IDEAL: VelocityBase = VelocityBase {
        spec: VelocityBaseSpec {
            tau_v: 0.0,
            tau_omega: 0.0,
            v_max: f64::INFINITY,
            omega_max: f64::INFINITY,
            a_max: f64::INFINITY,
            alpha_max: f64::INFINITY,
            accel: AccelLimit::Joint,
        },
    };

    /// ROBOTIS TurtleBot 3 Burger.
    ///
    /// - `v_max = 0.22 m/s`, `ω_max = 2.84 rad/s`: the ROBOTIS e-Manual,
    ///   TurtleBot3 "Specifications" (maximum translational / rotational
    ///   velocity), also `BURGER_MAX_LIN_VEL`/`BURGER_MAX_ANG_VEL` of
    ///   `turtlebot3_teleop`.
    /// - `a_max = 2.5 m/s²`, `α_max = 3.2 rad/s²`: `acc_lim_x`, `acc_lim_theta`
    ///   of `turtlebot3_navigation2/param/burger.yaml` (the Nav2 planner's
    ///   limits; ROBOTIS publishes no motor acceleration limit).
    /// - `τ_v = τ_ω = 0.1 s`: an estimate (Dynamixel XL430 velocity loop behind
    ///   the OpenCR board; no published time constant).
    pub const TURTLEBOT3_BURGER: VelocityBase = VelocityBase {
        spec: VelocityBaseSpec {
            tau_v: 0.1,
            tau_omega: 0.1,
            v_max: 0.22,
            omega_max: 2.84,
            a_max: 2.5,
            alpha_max: 3.2,
            accel: AccelLimit::Joint,
        },
    };

    /// Clearpath TurtleBot 4 (iRobot Create 3 base): the Create 3's own
    /// limits (iRobot's Create 3 documentation, quoted, not re-measured).
    ///
    /// - `v_max = 0.306 m/s`: the Create 3's top speed in safe mode (0.46 m/s
    ///   with `safety_override`, which also lifts its backup limit: set
    ///   `v_max` and `reverse_limit` yourself for that); `ω_max = 1.90
    ///   rad/s`: the TurtleBot 4 User Manual's hardware specifications.
    /// - `a_max = 0.9 m/s²`: the Create 3's wheel acceleration limit;
    ///   `α_max = 0.9 / l = 7.66 rad/s²`, the same wheel acceleration on its
    ///   235 mm track (joint limits keep the path, so a combined manoeuvre
    ///   never asks a wheel for more than it gives on one axis alone).
    /// - `τ_v = τ_ω = 0.1 s`: an estimate (no published time constant;
    ///   `echelon identify` measures it on a bag of the real base).
    /// - The Create 3 stops its wheels 0.5 s after its last `cmd_vel`
    ///   (the fleet's command period must be shorter: the scenario check
    ///   refuses a control rate that leaves less than two commands per
    ///   `cmd_vel_timeout`); it backs up at most ~10 cm without its safety
    ///   override ([`CREATE3_BACKUP_LIMIT`], the preset's `reverse_limit`).
    pub const TURTLEBOT4: VelocityBase = VelocityBase {
        spec: VelocityBaseSpec {
            tau_v: 0.1,
            tau_omega: 0.1,
            v_max: 0.306,
            omega_max: 1.90,
            a_max: 0.9,
            alpha_max: 0.9 / 0.1175,
            accel: AccelLimit::Joint,
        },
    };

    /// Clearpath Jackal.
    ///
    /// - `v_max = 2.0 m/s`, `ω_max = 4.0 rad/s`, `a_max = 20 m/s²`,
    ///   `α_max = 25 rad/s²`: `linear.x.max_velocity`, `angular.z.max_velocity`
    ///   and their `max_acceleration` in `jackal_control/config/control.yaml`
    ///   (the `diff_drive_controller` configuration Clearpath ships).
    /// - `τ_v = τ_ω = 0.05 s`: an estimate (no published time constant).
    pub const JACKAL: VelocityBase = VelocityBase {
        spec: VelocityBaseSpec {
            tau_v: 0.05,
            tau_omega: 0.05,
            v_max: 2.0,
            omega_max: 4.0,
            a_max: 20.0,
            alpha_max: 25.0,
            accel: AccelLimit::Joint,
        },
    };

    /// The base `spec`, checked: lags `τ_v`, `τ_ω` (s) finite and `≥ 0` (0:
    /// ideal, the axis follows the command); limits `v_max` (m/s), `ω_max`
    /// (rad/s), `a_max` (m/s²), `α_max` (rad/s²) `> 0` (infinite: unlimited,
    /// NaN refused); no finite acceleration limit on an axis without lag. The
    /// error names the first field refused.
    pub fn new(spec: VelocityBaseSpec) -> Result<VelocityBase, ParamError> {
        check(&spec)?;
        Ok(VelocityBase { spec })
    }

    /// The lags and limits as written (what [`VelocityBase::new`] takes back).
    #[inline]
    pub const fn spec(&self) -> VelocityBaseSpec {
        self.spec
    }

    /// The same base with its acceleration limits acting as `accel`.
    #[must_use]
    pub const fn with_accel(self, accel: AccelLimit) -> VelocityBase {
        VelocityBase {
            spec: VelocityBaseSpec { accel, ..self.spec },
        }
    }

    /// Lag of the linear speed `τ_v ≥ 0`, s (0: ideal, `v` follows the command).
    #[inline]
    pub const fn tau_v(&self) -> f64 {
        self.spec.tau_v
    }

    /// Lag of the angular speed `τ_ω ≥ 0`, s (0: ideal).
    #[inline]
    pub const fn tau_omega(&self) -> f64 {
        self.spec.tau_omega
    }

    /// Largest `|v|`, m/s (`> 0`, may be infinite).
    #[inline]
    pub const fn v_max(&self) -> f64 {
        self.spec.v_max
    }

    /// Largest `|ω|`, rad/s (`> 0`, may be infinite).
    #[inline]
    pub const fn omega_max(&self) -> f64 {
        self.spec.omega_max
    }

    /// Largest `|v̇|`, m/s² (`> 0`; finite only with `τ_v > 0`).
    #[inline]
    pub const fn a_max(&self) -> f64 {
        self.spec.a_max
    }

    /// Largest `|ω̇|`, rad/s² (`> 0`; finite only with `τ_ω > 0`).
    #[inline]
    pub const fn alpha_max(&self) -> f64 {
        self.spec.alpha_max
    }

    /// Joint (path-keeping, the default) or per-axis acceleration limits.
    #[inline]
    pub const fn accel(&self) -> AccelLimit {
        self.spec.accel
    }

    /// Checks that an RK4 step `dt` resolves the lags: every non-zero lag must
    /// be at least `dt` (a shorter one is better modelled as 0).
    pub fn check_step(&self, dt: f64) -> Result<(), ParamError> {
        for (field, tau) in [
            ("tau_v", self.spec.tau_v),
            ("tau_omega", self.spec.tau_omega),
        ] {
            if tau > 0.0 && tau < dt {
                return Err(ParamError::new(
                    field,
                    tau,
                    "is shorter than the integration step dt: use 0 (an ideal axis) or a smaller dt",
                ));
            }
        }
        Ok(())
    }

    /// Whether both axes follow the command without lag or limits (`V̇₁ = −K_e‖e‖²`
    /// holds exactly under the kinematic law).
    pub fn is_ideal(&self) -> bool {
        self.spec.tau_v == 0.0
            && self.spec.tau_omega == 0.0
            && self.spec.v_max == f64::INFINITY
            && self.spec.omega_max == f64::INFINITY
    }

    /// The speed limits, keeping the path: `(v, ω)` scaled by
    /// `k = min(1, v_max/|v|, ω_max/|ω|)`, so `ω/v` (the curvature) is kept and
    /// both limits hold exactly. Returns the command the base follows and
    /// whether it was saturated (`k < 1`). Identity within the limits.
    ///
    /// Acceleration limits act later, on how fast the base's velocity moves
    /// towards this command ([`VelocityBase::accelerations`]).
    #[inline]
    pub fn limit(&self, cmd: VelocityCommand) -> (VelocityCommand, bool) {
        let (av, aw) = (cmd.v.abs(), cmd.omega.abs());
        if av <= self.spec.v_max && aw <= self.spec.omega_max {
            return (cmd, false);
        }
        let k = (self.spec.v_max / av).min(self.spec.omega_max / aw);
        // The binding axis lands on its limit exactly; the clamps guard the
        // last bit of rounding in the product.
        let limited = VelocityCommand {
            v: (cmd.v * k).clamp(-self.spec.v_max, self.spec.v_max),
            omega: (cmd.omega * k).clamp(-self.spec.omega_max, self.spec.omega_max),
        };
        (limited, true)
    }

    /// The accelerations `(v̇, ω̇)` of the lagged axes towards the (limited)
    /// command `cmd`, after the acceleration limits (0 on an axis without lag,
    /// whose velocity is the command itself).
    #[inline]
    pub fn accelerations(&self, s: &State, cmd: VelocityCommand) -> (f64, f64) {
        let (dv, dw) = self.lag_rates(s, cmd);
        match self.spec.accel {
            AccelLimit::Joint => {
                let k = 1f64
                    .min(self.spec.a_max / dv.abs())
                    .min(self.spec.alpha_max / dw.abs());
                (
                    (dv * k).clamp(-self.spec.a_max, self.spec.a_max),
                    (dw * k).clamp(-self.spec.alpha_max, self.spec.alpha_max),
                )
            }
            AccelLimit::PerAxis => (
                dv.clamp(-self.spec.a_max, self.spec.a_max),
                dw.clamp(-self.spec.alpha_max, self.spec.alpha_max),
            ),
        }
    }

    /// Whether the acceleration limits cut the lags' response at this instant.
    #[inline]
    pub fn accel_limited(&self, s: &State, cmd: VelocityCommand) -> bool {
        let (dv, dw) = self.lag_rates(s, cmd);
        dv.abs() > self.spec.a_max || dw.abs() > self.spec.alpha_max
    }

    /// `(v_c − v)/τ_v` and `(ω_c − ω)/τ_ω`, 0 on an axis without lag.
    #[inline]
    fn lag_rates(&self, s: &State, cmd: VelocityCommand) -> (f64, f64) {
        let rate = |target: f64, now: f64, tau: f64| {
            if tau > 0.0 { (target - now) / tau } else { 0.0 }
        };
        (
            rate(cmd.v, s.v, self.spec.tau_v),
            rate(cmd.omega, s.omega, self.spec.tau_omega),
        )
    }

    /// The velocities the base moves at: the state's on a lagged axis, the
    /// command's on an axis without lag.
    #[inline]
    pub fn speeds(&self, s: &State, cmd: VelocityCommand) -> (f64, f64) {
        (
            if self.spec.tau_v > 0.0 { s.v } else { cmd.v },
            if self.spec.tau_omega > 0.0 {
                s.omega
            } else {
                cmd.omega
            },
        )
    }

    /// The state derivative `(ẋ, ẏ, θ̇, v̇, ω̇)` for the applied (already
    /// [limited](VelocityBase::limit)) command: eq. 1 at the base's
    /// [speeds](VelocityBase::speeds), and the lags' limited accelerations.
    #[inline]
    pub fn derivative(&self, s: &State, cmd: VelocityCommand) -> State {
        let (v, w) = self.speeds(s, cmd);
        let (dv, dw) = self.accelerations(s, cmd);
        let (sin, cos) = s.theta.sin_cos();
        State {
            x: v * cos,
            y: v * sin,
            theta: w,
            v: dv,
            omega: dw,
        }
    }

    /// The state after a step, made consistent with the command applied at
    /// its end: an axis without lag takes the command's velocity; a lagged
    /// velocity is kept within the speed limits (RK4 stays inside them when
    /// `dt ≤ τ`; this guards rounding).
    #[inline]
    pub fn settle(&self, s: &State, cmd: VelocityCommand) -> State {
        let (v, w) = self.speeds(s, cmd);
        State {
            v: v.clamp(-self.spec.v_max, self.spec.v_max),
            omega: w.clamp(-self.spec.omega_max, self.spec.omega_max),
            ..*s
        }
    }

    /// One RK4 step over `dt` with the applied command held (zero-order hold),
    /// then [settled](VelocityBase::settle).
    #[inline]
    pub fn rk4_step(&self, s: &State, cmd: VelocityCommand, dt: f64) -> State {
        self.settle(&s.rk4_step(dt, |x| self.derivative(x, cmd)), cmd)
    }
}

/// How far an iRobot Create 3 backs up without its safety override, m: it
/// refuses to drive further backwards (reporting `BACKUP_LIMIT`), since it
/// has no cliff sensor at the back (iRobot's `HazardDetection.msg`, "about
/// 10 cm" in the Create 3 documentation).
pub const CREATE3_BACKUP_LIMIT: f64 = 0.1;

mod backup;
mod robot;
pub use backup::Backup;
pub use robot::VelocityRobot;

#[cfg(test)]
mod tests;
