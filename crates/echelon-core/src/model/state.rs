//! A robot's state, pose and inputs: `(x, y, θ, v, ω)` in the world frame
//! {U}, `(u1, u2)` and the wheel torques.

use crate::error::ParamError;

/// Robot state `(x, y, θ, v, ω)` in the world frame {U}: position of the wheel
/// axle centre (m), heading (rad), linear speed (m/s) and angular speed (rad/s).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct State {
    /// x position, m.
    pub x: f64,
    /// y position, m.
    pub y: f64,
    /// Heading θ, rad (not wrapped: it is the integral of ω).
    pub theta: f64,
    /// Linear speed v, m/s.
    pub v: f64,
    /// Angular speed ω, rad/s.
    pub omega: f64,
}

impl State {
    /// This state as a start, refused when not finite (errors name
    /// `start.x`, …): what [`crate::AgentSpec`] and the engine's members start from.
    pub(crate) fn start(self) -> Result<State, ParamError> {
        for (field, v) in [
            ("start.x", self.x),
            ("start.y", self.y),
            ("start.theta", self.theta),
            ("start.v", self.v),
            ("start.omega", self.omega),
        ] {
            crate::check::finite(field, v)?;
        }
        Ok(self)
    }

    /// A robot at rest at pose `(x, y, θ)`.
    pub const fn at_rest(x: f64, y: f64, theta: f64) -> State {
        State {
            x,
            y,
            theta,
            v: 0.0,
            omega: 0.0,
        }
    }

    /// This state, given in a frame whose pose in the world is `origin`
    /// (REP 105: an `odom` frame's pose in `map`), in the world: the pose
    /// composed (`origin ⊕ pose`, heading continuous, unwrapped), the
    /// speeds (body frame) unchanged.
    pub fn carried_by(&self, origin: &Pose) -> State {
        let p = origin.compose(&self.pose());
        State {
            x: p.x,
            y: p.y,
            theta: p.theta,
            ..*self
        }
    }

    /// This world state in the frame whose world pose is `origin` (the
    /// inverse of [`State::carried_by`]).
    pub fn seen_from(&self, origin: &Pose) -> State {
        let p = origin.between(&self.pose());
        State {
            x: p.x,
            y: p.y,
            theta: p.theta,
            ..*self
        }
    }

    /// The pose part `(x, y, θ)`.
    #[inline]
    pub fn pose(&self) -> Pose {
        Pose {
            x: self.x,
            y: self.y,
            theta: self.theta,
        }
    }

    /// Position `p = [x, y]`.
    #[inline]
    pub fn position(&self) -> [f64; 2] {
        [self.x, self.y]
    }

    /// `self + k · d`, the RK4 stage update.
    #[inline]
    pub fn add_scaled(&self, d: &State, k: f64) -> State {
        State {
            x: self.x + k * d.x,
            y: self.y + k * d.y,
            theta: self.theta + k * d.theta,
            v: self.v + k * d.v,
            omega: self.omega + k * d.omega,
        }
    }

    /// `self + h6 (k₁ + 2 (k₂ + k₃) + k₄)`, the RK4 update from the four stage
    /// derivatives, with `h6 = dt/6`.
    #[inline]
    pub fn rk4_combine(&self, [a, b, c, d]: [&State; 4], h6: f64) -> State {
        State {
            x: self.x + h6 * (a.x + 2.0 * (b.x + c.x) + d.x),
            y: self.y + h6 * (a.y + 2.0 * (b.y + c.y) + d.y),
            theta: self.theta + h6 * (a.theta + 2.0 * (b.theta + c.theta) + d.theta),
            v: self.v + h6 * (a.v + 2.0 * (b.v + c.v) + d.v),
            omega: self.omega + h6 * (a.omega + 2.0 * (b.omega + c.omega) + d.omega),
        }
    }

    /// One classical RK4 step of `ẋ = f(x)` over `dt` from `self`.
    #[inline]
    pub fn rk4_step(&self, dt: f64, f: impl Fn(&State) -> State) -> State {
        let k1 = f(self);
        let k2 = f(&self.add_scaled(&k1, 0.5 * dt));
        let k3 = f(&self.add_scaled(&k2, 0.5 * dt));
        let k4 = f(&self.add_scaled(&k3, dt));
        self.rk4_combine([&k1, &k2, &k3, &k4], dt / 6.0)
    }

    /// Whether every component is finite.
    #[inline]
    pub fn is_finite(&self) -> bool {
        self.x.is_finite()
            && self.y.is_finite()
            && self.theta.is_finite()
            && self.v.is_finite()
            && self.omega.is_finite()
    }
}

/// A planar pose `(x, y, θ)`: m, m, rad.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct Pose {
    /// x, m.
    pub x: f64,
    /// y, m.
    pub y: f64,
    /// Heading, rad.
    pub theta: f64,
}

impl Pose {
    /// `self ⊕ d`: the pose reached by moving `d` expressed in this pose's frame.
    pub fn compose(&self, d: &Pose) -> Pose {
        let (s, c) = self.theta.sin_cos();
        Pose {
            x: self.x + c * d.x - s * d.y,
            y: self.y + s * d.x + c * d.y,
            theta: self.theta + d.theta,
        }
    }

    /// `self⁻¹ ⊕ other`: `other` expressed in this pose's frame.
    pub fn between(&self, other: &Pose) -> Pose {
        let (s, c) = self.theta.sin_cos();
        let (dx, dy) = (other.x - self.x, other.y - self.y);
        Pose {
            x: c * dx + s * dy,
            y: -s * dx + c * dy,
            theta: other.theta - self.theta,
        }
    }
}

/// Generalised control inputs `u = [u1, u2]` of eq. 3: force (N) and torque (N m).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct Input {
    /// `u1 = (τr + τl)/r`, N.
    pub u1: f64,
    /// `u2 = (l/r)(τr − τl)`, N m.
    pub u2: f64,
}

/// Wheel motor torques, N m.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct Torques {
    /// Right wheel torque `τr`.
    pub right: f64,
    /// Left wheel torque `τl`.
    pub left: f64,
}

impl Torques {
    /// `max(|τr|, |τl|)`.
    #[inline]
    pub fn peak(&self) -> f64 {
        self.right.abs().max(self.left.abs())
    }
}

/// Wraps an angle to `(−π, π]`.
#[inline]
pub fn wrap_angle(a: f64) -> f64 {
    use std::f64::consts::{PI, TAU};
    let w = a.rem_euclid(TAU);
    if w > PI { w - TAU } else { w }
}
