//! The divergence guard (issue 20): the physical bounds a robot's state must
//! stay within. A state that stops being finite or leaves them stops the run
//! (the simulator, the batch engine, the fleet robot) with one line naming the
//! agent, the time and what left its bound; a diverged agent is never reported
//! as a result.

use crate::check;
use crate::error::{Breach, ParamError};
use crate::model::State;

/// Bounds on a robot's state: `|v| ≤ speed`, `|ω| ≤ turn_rate`,
/// `‖(x, y)‖ ≤ distance`, every component finite. Far beyond any robot the
/// toolkit models: a state outside is a run that has blown up (a gain of 1e12,
/// a singular configuration), not a robot.
#[derive(Debug, Clone, Copy, PartialEq)]
#[non_exhaustive]
pub struct Bounds {
    /// Largest `|v|`, m/s.
    pub speed: f64,
    /// Largest `|ω|`, rad/s.
    pub turn_rate: f64,
    /// Largest distance from the world origin, m.
    pub distance: f64,
}

impl Default for Bounds {
    fn default() -> Bounds {
        Bounds::DEFAULT
    }
}

impl Bounds {
    /// 100 m/s, 100 rad/s, 10⁶ m.
    pub const DEFAULT: Bounds = Bounds {
        speed: 100.0,
        turn_rate: 100.0,
        distance: 1e6,
    };

    /// Refuses a bound that is not finite and `> 0`.
    pub fn new(speed: f64, turn_rate: f64, distance: f64) -> Result<Bounds, ParamError> {
        check::positive("speed", speed)?;
        check::positive("turn_rate", turn_rate)?;
        check::positive("distance", distance)?;
        Ok(Bounds {
            speed,
            turn_rate,
            distance,
        })
    }

    /// The first thing in `s` that is not finite or out of bounds, if any.
    #[inline]
    pub fn check(&self, s: &State) -> Option<Breach> {
        let inside = s.v.abs() <= self.speed
            && s.omega.abs() <= self.turn_rate
            && s.x * s.x + s.y * s.y <= self.distance * self.distance
            && s.theta.is_finite();
        if inside {
            return None;
        }
        let nan = |quantity, value: f64, unit| {
            (!value.is_finite()).then_some(Breach {
                quantity,
                value,
                bound: f64::INFINITY,
                unit,
            })
        };
        let over = |quantity, value: f64, bound: f64, unit| {
            (value > bound).then_some(Breach {
                quantity,
                value,
                bound,
                unit,
            })
        };
        nan("x", s.x, "m")
            .or_else(|| nan("y", s.y, "m"))
            .or_else(|| nan("theta", s.theta, "rad"))
            .or_else(|| nan("v", s.v, "m/s"))
            .or_else(|| nan("omega", s.omega, "rad/s"))
            .or_else(|| over("|v|", s.v.abs(), self.speed, "m/s"))
            .or_else(|| over("|omega|", s.omega.abs(), self.turn_rate, "rad/s"))
            .or_else(|| over("‖(x, y)‖", s.x.hypot(s.y), self.distance, "m"))
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use super::*;
    use proptest::prelude::*;

    #[test]
    fn each_quantity_is_named() {
        let b = Bounds::DEFAULT;
        let s = State::at_rest(1.0, 2.0, 0.3);
        assert_eq!(b.check(&s), None);
        let q = |s: State| b.check(&s).unwrap().quantity;
        assert_eq!(q(State { v: 101.0, ..s }), "|v|");
        assert_eq!(q(State { omega: -101.0, ..s }), "|omega|");
        assert_eq!(q(State { x: 1e6, ..s }), "‖(x, y)‖");
        assert_eq!(q(State { y: f64::NAN, ..s }), "y");
        assert_eq!(
            q(State {
                theta: f64::INFINITY,
                ..s
            }),
            "theta"
        );
        let line = b.check(&State { omega: 1e3, ..s }).unwrap().to_string();
        assert_eq!(line, "|omega| = 1.000e3 rad/s left its bound 100 rad/s");
        assert!(Bounds::new(0.0, 1.0, 1.0).is_err());
        assert!(Bounds::new(1.0, f64::INFINITY, 1.0).is_err());
    }

    proptest! {
        /// A state is accepted exactly when every component is finite and
        /// within its bound.
        #[test]
        fn accepted_iff_within(
            x in -2e6..2e6f64, y in -2e6..2e6f64, v in -200.0..200.0f64,
            omega in -200.0..200.0f64, theta in -10.0..10.0f64,
        ) {
            let s = State { x, y, theta, v, omega };
            let b = Bounds::DEFAULT;
            let within = v.abs() <= 100.0 && omega.abs() <= 100.0 && x.hypot(y) <= 1e6;
            prop_assert_eq!(b.check(&s).is_none(), within);
        }
    }
}
