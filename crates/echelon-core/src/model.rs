//! The plant: a differential-drive (unicycle) robot with its dynamic extension.
//!
//! Kinematics (paper eq. 1 / 3a–b) and dynamics (eq. 2 / 3c–d):
//!
//! ```text
//! ẋ = v cos θ     ẏ = v sin θ     θ̇ = ω
//! m v̇ = −η v + u1                  u1 = (τr + τl) / r
//! J ω̇ = −ψ ω + u2                  u2 = (l / r)(τr − τl)
//! ```
//!
//! The factor `l` in `u2` comes from eq. 2b (eq. 3 drops it; see
//! `docs/control-law.md`). All quantities are SI, angles in radians.

use crate::error::ParamError;

pub mod base;
mod state;
pub use state::{Input, Pose, State, Torques, wrap_angle};

/// The value named `name` in a table of named presets.
pub(crate) fn find_preset<T: Copy>(presets: &[(&str, T)], name: &str) -> Option<T> {
    presets.iter().find(|(n, _)| *n == name).map(|(_, p)| *p)
}

/// Physical parameters of one robot (paper Table I), as written: unchecked.
/// [`RobotParams::new`] checks them; a scenario's `[robots.NAME]` and the
/// serialised form of a [`RobotParams`] have these fields.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct RobotParamsSpec {
    /// Mass `m`, kg (finite, `> 0`).
    pub mass: f64,
    /// Viscous friction on the linear speed `η`, kg/s (finite, `≥ 0`).
    pub linear_friction: f64,
    /// Moment of inertia about the vertical axis `J`, kg m² (finite, `> 0`).
    pub inertia: f64,
    /// Viscous friction on the angular speed `ψ`, kg m²/s (finite, `≥ 0`).
    pub angular_friction: f64,
    /// Half the distance between the driving wheels `l`, m (finite, `> 0`).
    pub half_wheelbase: f64,
    /// Driving wheel radius `r`, m (finite, `> 0`).
    pub wheel_radius: f64,
    /// Largest torque magnitude each wheel motor can produce, N m (finite,
    /// `> 0`; `None`: unlimited).
    pub torque_limit: Option<f64>,
}

/// Physical parameters of one robot (paper Table I), checked.
///
/// Every value is physical: it can only be built through [`RobotParams::new`]
/// (and [`RobotParams::with_torque_limit`]), the presets, or deserialised
/// (which runs the same checks), so a `RobotParams` in hand is always valid.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(
    feature = "serde",
    serde(try_from = "RobotParamsSpec", into = "RobotParamsSpec")
)]
pub struct RobotParams {
    spec: RobotParamsSpec,
}

impl TryFrom<RobotParamsSpec> for RobotParams {
    type Error = ParamError;

    fn try_from(spec: RobotParamsSpec) -> Result<Self, ParamError> {
        RobotParams::new(spec)
    }
}

impl From<RobotParams> for RobotParamsSpec {
    fn from(p: RobotParams) -> RobotParamsSpec {
        p.spec
    }
}

/// Checks that every parameter is physical: mass, inertia, wheel radius and
/// half wheelbase strictly positive, frictions non-negative, the torque limit
/// (if any) strictly positive, everything finite.
fn check(p: &RobotParamsSpec) -> Result<(), ParamError> {
    use crate::check::{finite, positive, require};
    for (field, value) in [
        ("mass", p.mass),
        ("inertia", p.inertia),
        ("half_wheelbase", p.half_wheelbase),
        ("wheel_radius", p.wheel_radius),
    ] {
        require(field, finite(field, value)?, value > 0.0, "must be > 0")?;
    }
    for (field, value) in [
        ("linear_friction", p.linear_friction),
        ("angular_friction", p.angular_friction),
    ] {
        require(field, finite(field, value)?, value >= 0.0, "must be ≥ 0")?;
    }
    if let Some(limit) = p.torque_limit {
        positive("torque_limit", limit)?;
    }
    Ok(())
}

impl RobotParams {
    /// Table I, agent 1: `m = 27 kg, η = 180 kg/s, J = 1.42 kg m², ψ = 9.47 kg m²/s,
    /// l = 0.23 m, r = 0.101 m`.
    pub const AGENT1: RobotParams = RobotParams {
        spec: RobotParamsSpec {
            mass: 27.0,
            linear_friction: 180.0,
            inertia: 1.42,
            angular_friction: 9.47,
            half_wheelbase: 0.23,
            wheel_radius: 0.101,
            torque_limit: None,
        },
    };

    /// Table I, agent 2: `m = 25 kg, η = 133.7 kg/s, J = 1.03 kg m², ψ = 5.51 kg m²/s,
    /// l = 0.203 m, r = 0.10 m`.
    pub const AGENT2: RobotParams = RobotParams {
        spec: RobotParamsSpec {
            mass: 25.0,
            linear_friction: 133.7,
            inertia: 1.03,
            angular_friction: 5.51,
            half_wheelbase: 0.203,
            wheel_radius: 0.10,
            torque_limit: None,
        },
    };

    /// The named presets: `agent1` and `agent2` of Table I.
    pub const PRESETS: [(&'static str, RobotParams); 2] =
        [("agent1", Self::AGENT1), ("agent2", Self::AGENT2)];

    /// A preset by name (`agent1`, `agent2`).
    pub fn preset(name: &str) -> Option<RobotParams> {
        find_preset(&Self::PRESETS, name)
    }

    /// The robot `spec`, checked: mass `m` (kg), inertia `J` (kg m²), half
    /// wheelbase `l` (m) and wheel radius `r` (m) strictly positive, the
    /// frictions `η` (kg/s) and `ψ` (kg m²/s) non-negative, the torque limit
    /// (if any) strictly positive, everything finite. The error names the
    /// first field refused.
    pub fn new(spec: RobotParamsSpec) -> Result<RobotParams, ParamError> {
        check(&spec)?;
        Ok(RobotParams { spec })
    }

    /// The same robot with wheel motors limited to `±limit` N m each (`None`:
    /// unlimited); a limit must be a finite number > 0.
    pub fn with_torque_limit(self, limit: Option<f64>) -> Result<RobotParams, ParamError> {
        RobotParams::new(RobotParamsSpec {
            torque_limit: limit,
            ..self.spec
        })
    }

    /// The parameters as written (what [`RobotParams::new`] takes back).
    #[inline]
    pub const fn spec(&self) -> RobotParamsSpec {
        self.spec
    }

    /// Mass `m`, kg.
    #[inline]
    pub const fn mass(&self) -> f64 {
        self.spec.mass
    }

    /// Viscous friction on the linear speed `η`, kg/s.
    #[inline]
    pub const fn linear_friction(&self) -> f64 {
        self.spec.linear_friction
    }

    /// Moment of inertia about the vertical axis `J`, kg m².
    #[inline]
    pub const fn inertia(&self) -> f64 {
        self.spec.inertia
    }

    /// Viscous friction on the angular speed `ψ`, kg m²/s.
    #[inline]
    pub const fn angular_friction(&self) -> f64 {
        self.spec.angular_friction
    }

    /// Half the distance between the driving wheels `l`, m.
    #[inline]
    pub const fn half_wheelbase(&self) -> f64 {
        self.spec.half_wheelbase
    }

    /// Driving wheel radius `r`, m.
    #[inline]
    pub const fn wheel_radius(&self) -> f64 {
        self.spec.wheel_radius
    }

    /// Largest torque magnitude each wheel motor can produce, N m (`None`: unlimited).
    #[inline]
    pub const fn torque_limit(&self) -> Option<f64> {
        self.spec.torque_limit
    }

    /// Wheel torques from the generalised inputs: `τr = r(u1 + u2/l)/2`,
    /// `τl = r(u1 − u2/l)/2` (eq. 2 inverted).
    #[inline]
    pub fn torques(&self, u: Input) -> Torques {
        let r = self.spec.wheel_radius;
        let turn = u.u2 / self.spec.half_wheelbase;
        Torques {
            right: 0.5 * r * (u.u1 + turn),
            left: 0.5 * r * (u.u1 - turn),
        }
    }

    /// Generalised inputs from wheel torques: `u1 = (τr + τl)/r`,
    /// `u2 = (l/r)(τr − τl)` (eq. 2).
    #[inline]
    pub fn inputs(&self, tau: Torques) -> Input {
        let r = self.spec.wheel_radius;
        Input {
            u1: (tau.right + tau.left) / r,
            u2: self.spec.half_wheelbase * (tau.right - tau.left) / r,
        }
    }

    /// What the motors actually deliver for the commanded input: each wheel torque
    /// clamped to `±torque_limit` (identity without a limit).
    #[inline]
    pub fn actuate(&self, u: Input) -> (Input, Torques) {
        let tau = self.torques(u);
        match self.spec.torque_limit {
            None => (u, tau),
            Some(limit) => {
                let sat = Torques {
                    right: tau.right.clamp(-limit, limit),
                    left: tau.left.clamp(-limit, limit),
                };
                if sat == tau {
                    (u, tau)
                } else {
                    (self.inputs(sat), sat)
                }
            }
        }
    }

    /// A command the motors can deliver, keeping its turn: the wheel torques
    /// `τ_r,l = r (u1 ± u2/l)/2` (eq. 2) stay within `±torque_limit` by first
    /// limiting `u2` to what both wheels can give, then `u1` to what is left
    /// (identity without a limit, or when the command is within it). Clamping
    /// each wheel alone ([`RobotParams::actuate`]) drops the turn of a command
    /// that saturates both wheels the same way, and a robot driving away from
    /// its goal at full torque never turns back; the safety filter limits its
    /// nominal command with this first (as a velocity base's nominal goes
    /// through [`crate::model::base::VelocityBase::limit`]). Returns the command and
    /// whether it was cut.
    pub fn limit(&self, u: Input) -> (Input, bool) {
        let Some(limit) = self.spec.torque_limit else {
            return (u, false);
        };
        // |u1 ± u2/l| ≤ b
        let b = 2.0 * limit / self.spec.wheel_radius;
        let turn = u.u2 / self.spec.half_wheelbase;
        if u.u1.abs() + turn.abs() <= b {
            return (u, false);
        }
        let turn = turn.clamp(-b, b);
        let room = b - turn.abs();
        let out = Input {
            u1: u.u1.clamp(-room, room),
            u2: turn * self.spec.half_wheelbase,
        };
        (out, true)
    }

    /// The safety filter's friction brake in `s`: `u = (−η v, −ψ ω)`, twice
    /// friction's own deceleration.
    #[inline]
    pub fn brake(&self, s: &State) -> Input {
        Input {
            u1: -self.spec.linear_friction * s.v,
            u2: -self.spec.angular_friction * s.omega,
        }
    }

    /// Linear and angular accelerations `(v̇, ω̇)` for the applied input (eq. 3c–d).
    #[inline]
    pub fn accelerations(&self, s: &State, u: Input) -> (f64, f64) {
        (
            (u.u1 - self.spec.linear_friction * s.v) / self.spec.mass,
            (u.u2 - self.spec.angular_friction * s.omega) / self.spec.inertia,
        )
    }

    /// The state derivative for the applied input (eq. 3).
    #[inline]
    pub fn derivative(&self, s: &State, u: Input) -> State {
        let (dv, dw) = self.accelerations(s, u);
        let (sin, cos) = s.theta.sin_cos();
        State {
            x: s.v * cos,
            y: s.v * sin,
            theta: s.omega,
            v: dv,
            omega: dw,
        }
    }
}

impl RobotParams {
    /// One classical RK4 step of eq. 3 over `dt` with the applied input `u` held
    /// constant (zero-order hold): the plant between two controller samples.
    #[inline]
    pub fn rk4_step(&self, s: &State, u: Input, dt: f64) -> State {
        s.rk4_step(dt, |x| self.derivative(x, u))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    mod limit {
        use super::*;
        use proptest::prelude::*;

        proptest! {
            /// The limited command's wheel torques are within the limit, a
            /// command within it is returned as it is, the turn survives
            /// whenever the wheels can give it (and keeps its sign), and the
            /// drive never changes sign.
            #[test]
            fn wheels_within_turn_kept(
                u1 in -2000.0..2000.0f64,
                u2 in -300.0..300.0f64,
                limit in 0.5..50.0f64,
                agent2 in any::<bool>(),
            ) {
                let base = if agent2 { RobotParams::AGENT2 } else { RobotParams::AGENT1 };
                let p = base.with_torque_limit(Some(limit)).unwrap();
                let u = Input { u1, u2 };
                let (out, cut) = p.limit(u);
                let tau = p.torques(out);
                prop_assert!(tau.right.abs() <= limit * (1.0 + 1e-12));
                prop_assert!(tau.left.abs() <= limit * (1.0 + 1e-12));
                let inside = p.actuate(u).0 == u;
                prop_assert_eq!(!cut, inside);
                if !cut {
                    prop_assert_eq!(out, u);
                }
                let b = 2.0 * limit / p.wheel_radius();
                if (u2 / p.half_wheelbase()).abs() <= b {
                    prop_assert!((out.u2 - u2).abs() <= 1e-9 * u2.abs().max(1.0));
                }
                prop_assert!(out.u2 * u2 >= 0.0 && out.u1 * u1 >= 0.0);
                prop_assert!(out.u1.abs() <= u1.abs() && out.u2.abs() <= u2.abs() + 1e-9);
            }
        }

        #[test]
        fn without_a_limit_nothing_changes() {
            let u = Input { u1: 1e6, u2: -1e6 };
            assert_eq!(RobotParams::AGENT1.limit(u), (u, false));
        }
    }

    #[test]
    fn torque_mapping_round_trips() {
        for p in [RobotParams::AGENT1, RobotParams::AGENT2] {
            let u = Input {
                u1: 12.5,
                u2: -3.25,
            };
            let back = p.inputs(p.torques(u));
            assert!((back.u1 - u.u1).abs() < 1e-12 && (back.u2 - u.u2).abs() < 1e-12);
        }
    }

    #[test]
    fn torque_mapping_matches_eq_2() {
        let p = RobotParams::AGENT1;
        let tau = Torques {
            right: 2.0,
            left: 0.5,
        };
        let u = p.inputs(tau);
        assert!((u.u1 - 2.5 / 0.101).abs() < 1e-12);
        assert!((u.u2 - 0.23 * 1.5 / 0.101).abs() < 1e-12);
    }

    #[test]
    fn saturation_clamps_each_wheel() {
        let p = RobotParams::AGENT1.with_torque_limit(Some(1.0)).unwrap();
        let (u, tau) = p.actuate(p.inputs(Torques {
            right: 3.0,
            left: -0.5,
        }));
        assert_eq!(tau.right, 1.0);
        assert!(
            (tau.left + 0.5).abs() < 1e-12,
            "the unsaturated wheel is untouched"
        );
        let back = p.torques(u);
        assert!((back.right - 1.0).abs() < 1e-12 && (back.left + 0.5).abs() < 1e-12);
    }

    #[test]
    fn steady_state_speed_is_u_over_friction() {
        let p = RobotParams::AGENT2;
        let s = State {
            v: 0.5,
            omega: 0.1,
            ..State::default()
        };
        let u = Input {
            u1: p.linear_friction() * 0.5,
            u2: p.angular_friction() * 0.1,
        };
        let d = p.derivative(&s, u);
        assert!(d.v.abs() < 1e-12 && d.omega.abs() < 1e-12);
    }

    #[test]
    fn rk4_step_with_held_input_matches_the_closed_form() {
        // With u held, v(t) = u1/η + (v0 − u1/η) e^{−ηt/m} and likewise for ω
        // (eq. 3c–d are linear); RK4 is O(dt⁵) per step.
        let p = RobotParams::AGENT1;
        let u = Input { u1: 40.0, u2: -3.0 };
        let mut s = State {
            v: 0.1,
            omega: 0.2,
            ..State::default()
        };
        let dt = 0.01;
        for _ in 0..100 {
            s = p.rk4_step(&s, u, dt);
        }
        let t = 1.0;
        let v_inf = u.u1 / p.linear_friction();
        let w_inf = u.u2 / p.angular_friction();
        let v = v_inf + (0.1 - v_inf) * (-p.linear_friction() * t / p.mass()).exp();
        let w = w_inf + (0.2 - w_inf) * (-p.angular_friction() * t / p.inertia()).exp();
        assert!((s.v - v).abs() < 1e-8, "{} vs {v}", s.v);
        assert!((s.omega - w).abs() < 1e-8, "{} vs {w}", s.omega);
        // θ is the integral of ω.
        let theta = w_inf * t
            + (0.2 - w_inf) * p.inertia() / p.angular_friction()
                * (1.0 - (-p.angular_friction() * t / p.inertia()).exp());
        assert!((s.theta - theta).abs() < 1e-8);
    }

    #[test]
    fn invalid_parameters_are_refused() {
        let agent1 = RobotParams::AGENT1.spec();
        let with = |f: fn(&mut RobotParamsSpec)| {
            let mut spec = agent1;
            f(&mut spec);
            RobotParams::new(spec)
        };
        assert_eq!(with(|s| s.mass = -1.0).unwrap_err().field, "mass");
        assert_eq!(with(|s| s.inertia = f64::NAN).unwrap_err().field, "inertia");
        let neg_friction = with(|s| s.angular_friction = -0.1);
        assert!(neg_friction.is_err());
        let zero_limit = RobotParams::AGENT1.with_torque_limit(Some(0.0));
        assert_eq!(zero_limit.unwrap_err().field, "torque_limit");
        // Table I's values, in the paper's order `m, η, J, ψ, l, r`.
        for ([m, eta, j, psi, l, r], preset) in [
            ([27.0, 180.0, 1.42, 9.47, 0.23, 0.101], RobotParams::AGENT1),
            ([25.0, 133.7, 1.03, 5.51, 0.203, 0.10], RobotParams::AGENT2),
        ] {
            let spec = RobotParamsSpec {
                mass: m,
                linear_friction: eta,
                inertia: j,
                angular_friction: psi,
                half_wheelbase: l,
                wheel_radius: r,
                torque_limit: None,
            };
            assert_eq!(RobotParams::new(spec), Ok(preset));
            assert_eq!(preset.spec(), spec);
        }
    }

    #[test]
    fn wrap_angle_range() {
        use std::f64::consts::PI;
        assert!((wrap_angle(3.0 * PI) - PI).abs() < 1e-12);
        assert!((wrap_angle(-PI) - PI).abs() < 1e-12);
        assert!((wrap_angle(0.5) - 0.5).abs() < 1e-15);
        assert!((wrap_angle(-7.0) - (-7.0 + 2.0 * PI)).abs() < 1e-12);
    }
}

#[cfg(test)]
mod frame_tests {
    use super::*;
    use proptest::prelude::*;

    fn pose() -> impl Strategy<Value = Pose> {
        (-50.0..50.0f64, -50.0..50.0f64, -20.0..20.0f64).prop_map(|(x, y, theta)| Pose {
            x,
            y,
            theta,
        })
    }

    fn state() -> impl Strategy<Value = State> {
        (pose(), -2.0..2.0f64, -5.0..5.0f64).prop_map(|(p, v, omega)| State {
            x: p.x,
            y: p.y,
            theta: p.theta,
            v,
            omega,
        })
    }

    proptest! {
        /// `seen_from` undoes `carried_by`, and the speeds (body frame) are
        /// never touched.
        #[test]
        fn odom_to_world_round_trips(origin in pose(), s in state()) {
            let w = s.carried_by(&origin);
            prop_assert_eq!((w.v, w.omega), (s.v, s.omega));
            let back = w.seen_from(&origin);
            for (a, b) in [(back.x, s.x), (back.y, s.y), (back.theta, s.theta)] {
                prop_assert!((a - b).abs() < 1e-9 * (1.0 + b.abs() + origin.x.abs() + origin.y.abs()), "{back:?} vs {s:?}");
            }
        }

        /// The map is rigid: distances between two states and their
        /// relative heading are the same in both frames, and the heading
        /// turns by exactly the origin's (no wrapping: unwrapped headings
        /// stay continuous).
        #[test]
        fn odom_to_world_is_rigid(origin in pose(), a in state(), b in state()) {
            let (wa, wb) = (a.carried_by(&origin), b.carried_by(&origin));
            let d = (a.x - b.x).hypot(a.y - b.y);
            let wd = (wa.x - wb.x).hypot(wa.y - wb.y);
            prop_assert!((d - wd).abs() < 1e-9 * (1.0 + d), "{d} vs {wd}");
            prop_assert!((wa.theta - a.theta - origin.theta).abs() < 1e-12 * (1.0 + a.theta.abs() + origin.theta.abs()));
            // The odom frame's origin lands on the origin's position.
            let o = State::default().carried_by(&origin);
            prop_assert!((o.x - origin.x).abs() < 1e-12 && (o.y - origin.y).abs() < 1e-12);
        }
    }
}
