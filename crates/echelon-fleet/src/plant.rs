//! The robot a fleet process drives: the [`Plant`] trait, and the simulated
//! dynamic model (eq. 3) paced by the fleet clock.
//!
//! A real drive implements [`Plant`] by reading its odometry in `advance` and
//! `state` (it moves by itself) and sending wheel torques in `command`.

use echelon::model::{Input, RobotParams, State, Torques};

/// What the motors apply for a command.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Actuation {
    /// Applied generalised input (after torque saturation).
    pub u: Input,
    /// Applied wheel torques.
    pub tau: Torques,
}

/// A differential-drive robot under the fleet controller: what the robot's
/// state machine ([`crate::robot::Robot`]) drives, injected. The simulated
/// model is one; a real drive (wheel torques out, odometry in) or a
/// velocity-controlled base (its `cmd_vel` formed from `u`) is another.
pub trait Plant {
    /// The robot's state now (measured or simulated); `None` when the plant
    /// has no valid state (odometry lost), upon which the robot commands zero.
    fn state(&self) -> Option<State>;
    /// Brings the robot to fleet time `t`, the last command held in between
    /// (a real drive, which moves by itself, reads its odometry here).
    fn advance(&mut self, t: f64);
    /// Sends a command; it is held until the next one. Returns what the motors apply.
    fn command(&mut self, u: Input) -> Actuation;
    /// `(v̇, ω̇)` now.
    fn accelerations(&self) -> (f64, f64);
    /// The fleet clock was set to `t` (the leader's timeline began or
    /// restarted): the plant's time jumps there without moving. A real drive
    /// ignores it.
    fn set_time(&mut self, t: f64) {
        let _ = t;
    }
}

/// Eq. 3 integrated with RK4 over the real elapsed fleet time, in sub-steps
/// of at most `max_step`, with the last command held (zero-order hold).
#[derive(Debug, Clone)]
pub struct SimulatedPlant {
    params: RobotParams,
    state: State,
    applied: Input,
    t: f64,
    max_step: f64,
}

impl SimulatedPlant {
    /// A robot with `params` in state `start` at fleet time `t0`.
    pub fn new(params: RobotParams, start: State, t0: f64, max_step: f64) -> Self {
        SimulatedPlant {
            params,
            state: start,
            applied: Input::default(),
            t: t0,
            max_step,
        }
    }

    /// The simulated state (never lost).
    pub fn true_state(&self) -> State {
        self.state
    }
}

impl Plant for SimulatedPlant {
    fn state(&self) -> Option<State> {
        Some(self.state)
    }

    fn advance(&mut self, t: f64) {
        let span = t - self.t;
        if span <= 0.0 {
            return;
        }
        let n = (span / self.max_step).ceil().max(1.0) as u64;
        let h = span / n as f64;
        for _ in 0..n {
            self.state = self.params.rk4_step(&self.state, self.applied, h);
        }
        self.t = t;
    }

    fn command(&mut self, u: Input) -> Actuation {
        let (applied, tau) = self.params.actuate(u);
        self.applied = applied;
        Actuation { u: applied, tau }
    }

    fn accelerations(&self) -> (f64, f64) {
        self.params.accelerations(&self.state, self.applied)
    }

    fn set_time(&mut self, t: f64) {
        self.t = t;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn advancing_in_pieces_equals_advancing_at_once() {
        let p = RobotParams::AGENT2;
        let mut a = SimulatedPlant::new(p, State::at_rest(0.0, 0.0, 0.5), 0.0, 1e-3);
        let mut b = a.clone();
        let u = Input { u1: 30.0, u2: 1.0 };
        a.command(u);
        b.command(u);
        a.advance(0.1);
        for k in 1..=10 {
            b.advance(0.01 * k as f64);
        }
        let (sa, sb) = (a.true_state(), b.true_state());
        assert!((sa.x - sb.x).abs() < 1e-12 && (sa.theta - sb.theta).abs() < 1e-12);
        assert!(sa.v > 0.0 && sa.omega > 0.0);
        // Going back in time does nothing.
        a.advance(0.05);
        assert_eq!(a.true_state(), sa);
    }
}
