//! The deadlock monitor: when a robot the filter holds counts as stuck, and
//! how it breaks the deadlock (its desired motion turned right, see the
//! module documentation of [`crate::safety`]). The filter asks it
//! ([`super::SafetyFilter::decide`] in `filter.rs`); it knows nothing of the
//! filter.

/// How long after its filter last changed its command a robot still counts
/// as held by it ([`super::SafetyFilter::deadlocked`]), s.
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
    /// While breaking: how many times the turn of the desired motion left
    /// the robot standing still ([`Deadlock::record`], [`bias`]).
    turns: u8,
    /// Since when the robot, breaking, has stood still.
    still_since: Option<f64>,
    breaks: u64,
    /// The last time (s) the filter changed the command (stuck and breaking
    /// a deadlock only happen then).
    last: Option<f64>,
    /// The time of the last call.
    now: f64,
}

impl Deadlock {
    /// Whether the filter holds the robot: it changed the command at the
    /// last call or at any call within [`DEADLOCK_MEMORY`] before it.
    pub(super) fn held(&self) -> bool {
        self.last.is_some_and(|t| self.now - t <= DEADLOCK_MEMORY)
    }

    /// How many deadlocks it has started breaking.
    pub(super) fn breaks(&self) -> u64 {
        self.breaks
    }

    /// A call at `t` where the nominal satisfied every constraint: not
    /// stuck, not breaking.
    pub(super) fn free(&mut self, t: f64) {
        self.now = t;
        self.stuck_since = None;
        self.breaking = false;
        self.turns = 0;
        self.still_since = None;
    }

    /// A call at `t` where the filter acts: the desired motion for the QP
    /// (`x0`, turned right while breaking a deadlock) and whether it is
    /// breaking one.
    pub(super) fn want(&mut self, t: f64, x0: [f64; 2]) -> ([f64; 2], bool) {
        self.now = t;
        let want = if self.breaking {
            turn(x0, bias(self.turns))
        } else {
            x0
        };
        (want, self.breaking)
    }

    /// After the filter acted at `t`: whether the robot was `stuck`, and
    /// whether it stood `still` (the filtered point motion next to nothing
    /// of what the nominal asks); it starts breaking a deadlock after
    /// [`STUCK_TIME`] stuck. Breaking, a robot that stands still for
    /// [`STUCK_TIME`] tries the next turn of [`bias`] (left, then right and
    /// left by more): the right turn can point the desired motion where
    /// nothing is allowed (a torque robot at rest on a post's barrier,
    /// heading past its left side, may not reverse, and its right-turned
    /// desire pointed into the post, so the QP answered zero for ever),
    /// while some turn always has a part the rows allow, which moves it.
    pub(super) fn record(&mut self, t: f64, stuck: bool, still: bool) {
        if stuck {
            let since = *self.stuck_since.get_or_insert(t);
            if !self.breaking && t - since >= STUCK_TIME {
                self.breaking = true;
                self.breaks += 1;
            }
        } else {
            self.stuck_since = None;
        }
        if self.breaking && stuck && still {
            let since = *self.still_since.get_or_insert(t);
            if t - since >= STUCK_TIME {
                self.turns = (self.turns + 1) % BIASES;
                self.still_since = Some(t);
            }
        } else {
            self.still_since = None;
        }
        self.last = Some(t);
    }
}

/// How many turns [`bias`] tries before it starts again.
const BIASES: u8 = 7;

/// The turn of the desired motion while breaking a deadlock after `k`
/// turns left the robot standing still, rad (counter-clockwise): first
/// [`BIAS_ANGLE`] right (keep right), then left, then right and left by
/// twice and three times as much, then round (a half turn). Some turn of a
/// full circle has a part the rows allow whenever they allow any motion.
fn bias(k: u8) -> f64 {
    let size = f64::from(k / 2 + 1) * BIAS_ANGLE;
    let size = size.min(std::f64::consts::PI);
    if k.is_multiple_of(2) { -size } else { size }
}

/// `x` turned counter-clockwise by `angle` (the body frame and the world
/// frame turn together).
fn turn(x: [f64; 2], angle: f64) -> [f64; 2] {
    let (s, c) = angle.sin_cos();
    [c * x[0] - s * x[1], s * x[0] + c * x[1]]
}
