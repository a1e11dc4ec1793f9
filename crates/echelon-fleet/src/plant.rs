//! The robot a fleet process drives: the [`Plant`] trait, the simulated
//! dynamic model (eq. 3) and the simulated velocity base
//! ([`echelon::base::VelocityBase`]), both paced by the fleet clock.
//!
//! A real drive implements [`Plant`] by reading its odometry in `advance` and
//! `state` (it moves by itself) and sending its command in `command`: the ROS
//! 2 drive ([`crate::ros2::drive::Ros2Drive`]) publishes `cmd_vel`.

pub use echelon::agent::{Actuation, Command};
use echelon::agent::{AgentSpec, Drive};
use echelon::base::{VelocityBase, VelocityCommand};
use echelon::model::{Input, RobotParams, State};

use crate::ros2::fixes::FixReport;
use crate::wire::OdometryState;

/// A differential-drive robot under the fleet controller: what the robot's
/// state machine ([`crate::robot::Robot`]) drives, injected. The simulated
/// models are two; a real drive (ROS 2 `cmd_vel` out, odometry in) is another.
pub trait Plant {
    /// The robot's state now (measured or simulated); `None` when the plant
    /// has no valid state (odometry lost), upon which the robot commands zero.
    fn state(&self) -> Option<State>;
    /// Brings the robot to fleet time `t`, the last command held in between
    /// (a real drive, which moves by itself, notes the time here).
    fn advance(&mut self, t: f64);
    /// Sends a command; it is held until the next one. Returns what the motors apply.
    fn command(&mut self, cmd: Command) -> Actuation;
    /// Commands zero in the drive's own terms (zero torques, or a zero
    /// velocity command sent now): losing the leader, the odometry or the
    /// process.
    fn stop(&mut self);
    /// `(v̇, ω̇)` now.
    fn accelerations(&self) -> (f64, f64);
    /// The fleet clock was set to `t` (the leader's timeline began or
    /// restarted): the plant's time jumps there without moving.
    fn set_time(&mut self, t: f64) {
        let _ = t;
    }
    /// The standard deviation of its position estimate along the most
    /// uncertain axis, m (0: exact, as a simulated plant, or unknown).
    fn position_sigma(&self) -> f64 {
        0.0
    }
    /// Its own odometry, raw (its odom frame), with its age and its last
    /// fix's, now (`None`: a simulated plant, or no odometry yet).
    fn odometry(&self) -> Option<OdometryState> {
        None
    }
    /// What its absolute fixes did, at fleet time `t` (`None`: it takes
    /// none, as a simulated plant, which is never lost).
    fn fixes(&self, t: f64) -> Option<FixReport> {
        let _ = t;
        None
    }
}

/// Steps `state` from `from` to `to` in equal steps of at most `max_step`
/// (`step(state, h)`); returns the new time (`from` when `to` is not later).
fn integrate(
    state: &mut State,
    from: f64,
    to: f64,
    max_step: f64,
    step: impl Fn(&State, f64) -> State,
) -> f64 {
    let span = to - from;
    if span <= 0.0 {
        return from;
    }
    let n = (span / max_step).ceil().max(1.0) as u64;
    let h = span / n as f64;
    for _ in 0..n {
        *state = step(state, h);
    }
    to
}

/// A model a [`Simulated`] plant integrates: eq. 3 ([`RobotParams`], wheel
/// torques) or a velocity base ([`VelocityBase`], velocity commands).
pub trait Model: Copy + std::fmt::Debug {
    /// The input it holds between commands (after its limits).
    type Held: Copy + Default + PartialEq + std::fmt::Debug;
    /// The command that stops it, in its own terms.
    const ZERO: Command;
    /// What `cmd` makes it hold from state `state` (a velocity base settles
    /// `state` to it), and what the motors apply; a command of the other
    /// kind is zero (the robot never sends one: its law is its drive's).
    fn apply(&self, state: &mut State, cmd: Command) -> (Self::Held, Actuation);
    /// One RK4 step of `h` from `s`, `held` held.
    fn rk4_step(&self, s: &State, held: Self::Held, h: f64) -> State;
    /// `(v̇, ω̇)` in `s` with `held` held.
    fn accelerations(&self, s: &State, held: Self::Held) -> (f64, f64);
}

impl Model for RobotParams {
    type Held = Input;
    const ZERO: Command = Command::Torque(Input { u1: 0.0, u2: 0.0 });

    fn apply(&self, _state: &mut State, cmd: Command) -> (Input, Actuation) {
        let u = match cmd {
            Command::Torque(u) => u,
            Command::Velocity(_) => Input::default(),
        };
        let (applied, tau) = self.actuate(u);
        let actuation = Actuation {
            u: applied,
            tau,
            velocity: None,
        };
        (applied, actuation)
    }

    fn rk4_step(&self, s: &State, held: Input, h: f64) -> State {
        RobotParams::rk4_step(self, s, held, h)
    }

    fn accelerations(&self, s: &State, held: Input) -> (f64, f64) {
        RobotParams::accelerations(self, s, held)
    }
}

impl Model for VelocityBase {
    type Held = VelocityCommand;
    const ZERO: Command = Command::Velocity(VelocityCommand { v: 0.0, omega: 0.0 });

    /// The command limited as the simulator limits it
    /// ([`echelon::sim::Simulation`]), so the fleet and the simulator move
    /// the same base.
    fn apply(&self, state: &mut State, cmd: Command) -> (VelocityCommand, Actuation) {
        let cmd = match cmd {
            Command::Velocity(c) => c,
            Command::Torque(_) => VelocityCommand::default(),
        };
        let (applied, saturated) = self.limit(cmd);
        *state = self.settle(state, applied);
        let actuation = Actuation {
            velocity: Some((applied, saturated)),
            ..Actuation::default()
        };
        (applied, actuation)
    }

    fn rk4_step(&self, s: &State, held: VelocityCommand, h: f64) -> State {
        VelocityBase::rk4_step(self, s, held, h)
    }

    fn accelerations(&self, s: &State, held: VelocityCommand) -> (f64, f64) {
        VelocityBase::accelerations(self, s, held)
    }
}

/// A [`Model`] integrated with RK4 over the real elapsed fleet time, in
/// sub-steps of at most `max_step`, the last command held (zero-order
/// hold).
#[derive(Debug, Clone)]
pub struct Simulated<M: Model> {
    model: M,
    state: State,
    applied: M::Held,
    t: f64,
    max_step: f64,
}

/// Eq. 3, simulated.
pub type SimulatedPlant = Simulated<RobotParams>;

/// A velocity-controlled base ([`VelocityBase`]: first-order lags, speed
/// and acceleration limits), simulated.
pub type SimulatedVelocityBase = Simulated<VelocityBase>;

impl<M: Model> Simulated<M> {
    /// A robot moving as `model` in state `start` at fleet time `t0`.
    pub fn new(model: M, start: State, t0: f64, max_step: f64) -> Self {
        Simulated {
            model,
            state: start,
            applied: M::Held::default(),
            t: t0,
            max_step,
        }
    }

    /// The simulated state (never lost): pose, and the speeds it moves at.
    pub fn true_state(&self) -> State {
        self.state
    }

    /// The input it holds now (after its limits).
    pub fn applied(&self) -> M::Held {
        self.applied
    }
}

impl Simulated<VelocityBase> {
    /// Follows `cmd` from now on; returns it after the speed limits and
    /// whether they cut it.
    pub fn follow(&mut self, cmd: VelocityCommand) -> (VelocityCommand, bool) {
        self.command(Command::Velocity(cmd))
            .velocity
            .unwrap_or_default()
    }
}

impl<M: Model> Plant for Simulated<M> {
    fn state(&self) -> Option<State> {
        Some(self.state)
    }

    fn advance(&mut self, t: f64) {
        let (model, applied) = (self.model, self.applied);
        self.t = integrate(&mut self.state, self.t, t, self.max_step, |s, h| {
            model.rk4_step(s, applied, h)
        });
    }

    fn command(&mut self, cmd: Command) -> Actuation {
        let (applied, actuation) = self.model.apply(&mut self.state, cmd);
        self.applied = applied;
        actuation
    }

    fn stop(&mut self) {
        self.command(M::ZERO);
    }

    fn accelerations(&self) -> (f64, f64) {
        self.model.accelerations(&self.state, self.applied)
    }

    fn set_time(&mut self, t: f64) {
        self.t = t;
    }
}

/// The simulated robot of an agent: eq. 3 for a torque-driven one, its
/// velocity base for the others.
#[derive(Debug, Clone)]
pub enum SimulatedDrive {
    /// Eq. 3.
    Torque(SimulatedPlant),
    /// A velocity base.
    Velocity(SimulatedVelocityBase),
}

impl SimulatedDrive {
    /// Agent `spec`'s robot at its start, at fleet time `t0`.
    pub fn of(spec: &AgentSpec, t0: f64, max_step: f64) -> Self {
        match &spec.drive() {
            Drive::Torque { robot, .. } => {
                SimulatedDrive::Torque(SimulatedPlant::new(*robot, spec.start(), t0, max_step))
            }
            Drive::Velocity(r) => SimulatedDrive::Velocity(SimulatedVelocityBase::new(
                r.base(),
                spec.start(),
                t0,
                max_step,
            )),
        }
    }

    /// The simulated state.
    pub fn true_state(&self) -> State {
        match self {
            SimulatedDrive::Torque(p) => p.true_state(),
            SimulatedDrive::Velocity(b) => b.true_state(),
        }
    }

    fn plant(&mut self) -> &mut dyn Plant {
        match self {
            SimulatedDrive::Torque(p) => p,
            SimulatedDrive::Velocity(b) => b,
        }
    }

    fn plant_ref(&self) -> &dyn Plant {
        match self {
            SimulatedDrive::Torque(p) => p,
            SimulatedDrive::Velocity(b) => b,
        }
    }
}

impl Plant for SimulatedDrive {
    fn state(&self) -> Option<State> {
        self.plant_ref().state()
    }
    fn advance(&mut self, t: f64) {
        self.plant().advance(t);
    }
    fn command(&mut self, cmd: Command) -> Actuation {
        self.plant().command(cmd)
    }
    fn stop(&mut self) {
        self.plant().stop();
    }
    fn accelerations(&self) -> (f64, f64) {
        self.plant_ref().accelerations()
    }
    fn set_time(&mut self, t: f64) {
        self.plant().set_time(t);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use echelon::base::VelocityBaseSpec;

    #[test]
    fn advancing_in_pieces_equals_advancing_at_once() {
        let p = RobotParams::AGENT2;
        let mut a = SimulatedPlant::new(p, State::at_rest(0.0, 0.0, 0.5), 0.0, 1e-3);
        let mut b = a.clone();
        let u = Command::Torque(Input { u1: 30.0, u2: 1.0 });
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

    /// The fleet's base is the simulator's: an ideal base turns exactly on
    /// the commanded circle; a lagged one approaches the command as
    /// `1 − e^{−t/τ}` (its closed form) while staying within its limits.
    #[test]
    fn a_velocity_base_follows_its_command_as_the_model_says() {
        let ideal = VelocityBase::IDEAL;
        let mut b = SimulatedVelocityBase::new(ideal, State::at_rest(0.0, 0.0, 0.0), 0.0, 1e-3);
        let c = VelocityCommand { v: 0.4, omega: 0.5 };
        let act = b.command(Command::Velocity(c));
        assert_eq!(act.velocity, Some((c, false)));
        b.advance(1.0);
        let s = b.true_state();
        let r = 0.4 / 0.5;
        assert!((s.x - r * 0.5f64.sin()).abs() < 1e-9, "{s:?}");
        assert!((s.y - r * (1.0 - 0.5f64.cos())).abs() < 1e-9, "{s:?}");
        assert_eq!((s.v, s.omega), (0.4, 0.5));

        let lagged = VelocityBase::new(VelocityBaseSpec {
            tau_v: 0.2,
            tau_omega: 0.1,
            ..VelocityBase::IDEAL.spec()
        })
        .expect("a lagged base");
        let mut b = SimulatedVelocityBase::new(lagged, State::at_rest(0.0, 0.0, 0.0), 0.0, 1e-3);
        b.command(Command::Velocity(c));
        b.advance(0.3);
        let s = b.true_state();
        assert!(
            (s.v - 0.4 * (1.0 - (-0.3f64 / 0.2).exp())).abs() < 1e-9,
            "{s:?}"
        );
        assert!(
            (s.omega - 0.5 * (1.0 - (-0.3f64 / 0.1).exp())).abs() < 1e-9,
            "{s:?}"
        );
        // Beyond the limits: scaled together (curvature kept), and held.
        let limited = VelocityBase::new(VelocityBaseSpec {
            tau_v: 0.2,
            tau_omega: 0.1,
            v_max: 0.2,
            omega_max: 1.0,
            ..VelocityBase::IDEAL.spec()
        })
        .expect("a lagged base with speed limits");
        let mut b = SimulatedVelocityBase::new(limited, State::at_rest(0.0, 0.0, 0.0), 0.0, 1e-3);
        let act = b.command(Command::Velocity(c));
        let (applied, saturated) = act.velocity.expect("a velocity base");
        assert!(saturated);
        assert_eq!(applied.v, 0.2);
        assert!((applied.omega / applied.v - c.omega / c.v).abs() < 1e-12);
        b.advance(5.0);
        assert!(b.true_state().v <= 0.2);
        b.stop();
        assert_eq!(b.applied(), VelocityCommand::default());
    }
}
