//! The robot a fleet process drives: the [`Plant`] trait and the simulated
//! robot ([`SimulatedDrive`]: the core's [`Drive`], eq. 3 or a velocity base,
//! paced by the fleet clock).
//!
//! A real drive implements [`Plant`] by reading its odometry in `advance` and
//! `state` (it moves by itself) and sending its command in `command`: the ROS
//! 2 drive ([`crate::ros2::drive::Ros2Drive`]) publishes `cmd_vel`.

pub use echelon::agent::{Actuation, Command};
use echelon::agent::{AgentSpec, Drive};
use echelon::base::VelocityCommand;
use echelon::model::State;

use crate::faults::{Aftermath, AftermathReport, FaultSpec};
use crate::ros2::fixes::FixReport;
use crate::ros2::hazard::{HazardReport, HazardSet};
use crate::wire::OdometryState;

/// A differential-drive robot under the fleet controller: what the robot's
/// state machine ([`crate::robot::Robot`]) drives, injected: the simulated
/// robot ([`SimulatedDrive`]), or a real drive (ROS 2 `cmd_vel` out, odometry
/// in).
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
    /// The age of the measurement behind [`Plant::state`] at its time, s
    /// (`None`: nothing measured yet). The robot's odometry watchdog
    /// ([`crate::robot::Watchdog::Odometry`]) holds it when this exceeds
    /// its `odom_timeout`. By default a plant's state is current whenever
    /// it has one (0); a simulated plant's is 0 unless frozen.
    fn odometry_age(&self) -> Option<f64> {
        self.state().map(|_| 0.0)
    }
    /// Whether its commands have lost their reader (a ROS 2 base's
    /// `cmd_vel` subscriber gone), which the robot's output watchdog holds
    /// it for ([`crate::robot::Watchdog::Output`]); `false` (the default)
    /// where it cannot tell or nothing else reads (a simulated plant).
    fn command_reader_lost(&self) -> bool {
        false
    }
    /// What the robot did after an injected fault (`None`: not measured).
    fn aftermath(&self) -> Option<AftermathReport> {
        None
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
    /// The base's own stopping safety words in force at fleet time `t` (a
    /// bump, a cliff, a stall, a wheel drop, an e-stop:
    /// [`crate::ros2::hazard`]), its events brought up to `t`; none on a
    /// plant that has no such sensors, as a simulated one.
    fn hazards(&mut self, t: f64) -> HazardSet {
        let _ = t;
        HazardSet::EMPTY
    }
    /// What its base's safety words did (`None`: it listens to none).
    fn hazard_report(&self) -> Option<HazardReport> {
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

/// An agent's robot, simulated: its [`Drive`] (eq. 3 under wheel torques, or
/// a velocity base's lags and limits) integrated with RK4
/// ([`Drive::rk4_step`]) over the real elapsed fleet time, in sub-steps of at
/// most `max_step`, the last command held (zero-order hold). A command goes
/// through the drive's limits ([`Drive::actuate`]) and settles the state to
/// what is applied ([`Drive::settle`]), as in the simulator
/// ([`echelon::sim::Simulation`]): the fleet and the simulator move the same
/// robot.
#[derive(Debug, Clone)]
pub struct SimulatedDrive {
    drive: Drive,
    state: State,
    applied: Actuation,
    t: f64,
    max_step: f64,
    /// `--freeze-odometry`: the window, and the state and time it froze at.
    freeze: Option<(f64, f64)>,
    frozen: Option<(State, f64)>,
    /// `--fault-at`: what it does from the fault on.
    aftermath: Option<Aftermath>,
}

impl SimulatedDrive {
    /// A robot driven as `drive` in state `start` at fleet time `t0`,
    /// applying zero ([`Drive::zero`]).
    pub fn new(drive: Drive, start: State, t0: f64, max_step: f64) -> Self {
        SimulatedDrive {
            drive,
            state: start,
            applied: drive.actuate(drive.zero()),
            t: t0,
            max_step,
            freeze: None,
            frozen: None,
            aftermath: None,
        }
    }

    /// The same robot under the process's own faults: its odometry frozen
    /// in `faults.freeze_odometry`, its aftermath measured from
    /// `faults.fault_at`.
    pub fn with_faults(self, faults: &FaultSpec) -> Self {
        SimulatedDrive {
            freeze: faults.freeze_odometry,
            aftermath: faults
                .fault_at
                .map(|at| Aftermath::new(at, faults.fault_window)),
            ..self
        }
    }

    /// Measures what it does from its time `at` on, for `window` s
    /// ([`Aftermath`]), from now.
    pub fn measure_from(&mut self, at: f64, window: Option<f64>) {
        self.aftermath = Some(Aftermath::new(at, window));
    }

    fn observe(&mut self) {
        let (t, s, zero) = (
            self.t,
            self.state,
            self.applied == self.drive.actuate(self.drive.zero()),
        );
        if let Some(m) = self.aftermath.as_mut() {
            m.observe(t, [s.x, s.y], s.v.abs(), zero);
        }
        let frozen = self
            .freeze
            .is_some_and(|(start, len)| t >= start && t < start + len);
        match (frozen, self.frozen) {
            (true, None) => self.frozen = Some((s, t)),
            (false, Some(_)) => self.frozen = None,
            _ => {}
        }
    }

    /// Agent `spec`'s robot at its start, at fleet time `t0`.
    pub fn of(spec: &AgentSpec, t0: f64, max_step: f64) -> Self {
        Self::new(*spec.drive(), spec.start(), t0, max_step)
    }

    /// The simulated state (never lost): pose, and the speeds it moves at.
    pub fn true_state(&self) -> State {
        self.state
    }

    /// What its motors apply now (after the drive's limits).
    pub fn applied(&self) -> Actuation {
        self.applied
    }

    /// Follows the velocity command `cmd` from now on; returns it after the
    /// speed limits and whether they cut it (a velocity base; a
    /// torque-driven robot applies zero and returns zero, uncut).
    pub fn follow(&mut self, cmd: VelocityCommand) -> (VelocityCommand, bool) {
        self.command(Command::Velocity(cmd))
            .velocity
            .unwrap_or_default()
    }
}

impl Plant for SimulatedDrive {
    /// Its simulated state, or where it froze (`--freeze-odometry`).
    fn state(&self) -> Option<State> {
        Some(self.frozen.map_or(self.state, |(s, _)| s))
    }

    fn advance(&mut self, t: f64) {
        let (drive, applied) = (self.drive, self.applied);
        self.t = integrate(&mut self.state, self.t, t, self.max_step, |s, h| {
            drive.rk4_step(s, &applied, h)
        });
        self.observe();
    }

    fn odometry_age(&self) -> Option<f64> {
        Some(self.frozen.map_or(0.0, |(_, at)| self.t - at))
    }

    fn aftermath(&self) -> Option<AftermathReport> {
        self.aftermath.as_ref().map(Aftermath::report)
    }

    fn command(&mut self, cmd: Command) -> Actuation {
        self.applied = self.drive.actuate(cmd);
        self.state = self.drive.settle(&self.state, &self.applied);
        self.observe();
        self.applied
    }

    fn stop(&mut self) {
        self.command(self.drive.zero());
    }

    fn accelerations(&self) -> (f64, f64) {
        let d = self.drive.derivative(&self.state, &self.applied);
        (d.v, d.omega)
    }

    fn set_time(&mut self, t: f64) {
        self.t = t;
    }
}

#[cfg(test)]
mod tests;
