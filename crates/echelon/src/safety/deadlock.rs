//! The deadlock monitor: when a robot the filter holds counts as stuck, and
//! how it breaks the deadlock (its desired motion turned right, see the
//! module documentation of [`crate::safety`]).

use super::filter::{Outcome, SafetyFilter};
use super::qp::{Constraint, solve};

/// How long after its filter last changed its command a robot still counts
/// as held by it ([`SafetyFilter::deadlocked`]), s.
pub const DEADLOCK_MEMORY: f64 = 10.0;

/// How long a robot must be stuck before it breaks a deadlock, s.
pub const STUCK_TIME: f64 = 1.0;

/// How far the desired point motion is turned clockwise while breaking a
/// deadlock, rad.
pub const BIAS_ANGLE: f64 = std::f64::consts::FRAC_PI_4;

/// Deadlock monitor state.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub(super) struct Deadlock {
    stuck_since: Option<f64>,
    breaking: bool,
    breaks: u64,
    /// The last time (s) the filter changed the command (stuck and breaking
    /// a deadlock only happen then).
    last: Option<f64>,
    /// The time of the last call.
    now: f64,
}

impl SafetyFilter {
    /// Whether the filter holds the robot: it changed the command (and so
    /// may be stuck or breaking a deadlock) at its last call or at any call
    /// within [`DEADLOCK_MEMORY`] before it (a robot that keeps falling back
    /// into the same stand-off between breaks, or rides along a neighbour's
    /// barrier beside its slot, is held too).
    pub fn deadlocked(&self) -> bool {
        let d = &self.deadlock;
        d.last.is_some_and(|t| d.now - t <= DEADLOCK_MEMORY)
    }

    /// How many deadlocks it has started breaking.
    pub fn deadlock_breaks(&self) -> u64 {
        self.deadlock.breaks
    }

    /// The QP's answer for the desired `x0` and the rows gathered, the
    /// outcome and whether a deadlock is being broken; updates the monitor.
    /// `drift` is the part of the point's motion the command does not set
    /// (zero for velocity bases), for the stuck test.
    pub(super) fn decide(
        &mut self,
        t: f64,
        x0: [f64; 2],
        barriers: usize,
        drift: [f64; 2],
    ) -> ([f64; 2], Outcome, bool) {
        let satisfied = |rows: &[Constraint], x: [f64; 2]| rows.iter().all(|c| c.slack(x) >= 0.0);
        self.deadlock.now = t;
        if satisfied(&self.rows[..barriers], x0) {
            self.deadlock.stuck_since = None;
            self.deadlock.breaking = false;
            return (x0, Outcome::Nominal, false);
        }
        let breaking = self.deadlock.breaking;
        let want = if breaking { turn_right(x0) } else { x0 };
        let (x, outcome) = match solve(&self.rows, want) {
            Some(x) => (x, Outcome::Filtered),
            None => ([0.0; 2], Outcome::Braked),
        };
        // Stuck: less than half of the motion the nominal asks for survives
        // (the point stops, or slides alongside a neighbour it should pass).
        let moved = [x[0] + drift[0], x[1] + drift[1]];
        let asked = [x0[0] + drift[0], x0[1] + drift[1]];
        let asked_sq = asked[0] * asked[0] + asked[1] * asked[1];
        let stuck = asked_sq >= 1e-4 && moved[0] * asked[0] + moved[1] * asked[1] < 0.5 * asked_sq;
        if stuck {
            let since = *self.deadlock.stuck_since.get_or_insert(t);
            if !self.deadlock.breaking && t - since >= STUCK_TIME {
                self.deadlock.breaking = true;
                self.deadlock.breaks += 1;
            }
        } else {
            self.deadlock.stuck_since = None;
        }
        self.deadlock.last = Some(t);
        (x, outcome, breaking)
    }
}

/// `x` turned clockwise by [`BIAS_ANGLE`] (the body frame and the world frame
/// turn together).
fn turn_right(x: [f64; 2]) -> [f64; 2] {
    let (s, c) = BIAS_ANGLE.sin_cos();
    [c * x[0] + s * x[1], -s * x[0] + c * x[1]]
}
