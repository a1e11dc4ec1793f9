//! The deadlock monitor: when a robot the filter holds counts as stuck, and
//! how it breaks the deadlock (its desired motion turned right, see the
//! module documentation of [`crate::safety`]). The filter asks it
//! ([`super::SafetyFilter::decide`] in `filter.rs`); it knows nothing of the
//! filter.
//!
//! Two tests, on two signals. *Motion* (every call): less than half of the
//! point motion the nominal asks for survives ([`Deadlock::record`]'s
//! `stuck`), or next to none of it and the point stands (`still`). *Progress*
//! (over a window, when the caller gives the law's tracking error
//! ‖e‖, [`super::SafetyFilter::set_tracking_error`]): the filter keeps acting,
//! ‖e‖ does not fall by [`PROGRESS_FRACTION`] in [`PROGRESS_WINDOW`], and the
//! point does not move relative to what holds it by that fraction of ‖e‖.
//! The second catches what the first cannot: a robot whose slot lies across
//! a neighbour that holds its own slot rides beside it at the formation's
//! speed, the filter taking away only the push toward the slot (`e` along
//! the pair's `d`): the feed-forward, most of what the nominal asks, survives,
//! so the robot never counts as stuck, and ‖e‖ stays where it is for ever
//! (an equilibrium of the filtered loop, not of the law).
//!
//! In an *encounter* (the nominal closes on an oncoming neighbour faster
//! than their barrier allows; the filter tells, it knows the rows) the
//! motion test is stricter and acts at once ([`ENCOUNTER_SHARE`]): dense
//! symmetric crowds keep right before they jam.

/// How long after its filter last changed its command a robot still counts
/// as held by it ([`super::SafetyFilter::deadlocked`]), s.
pub const DEADLOCK_MEMORY: f64 = 10.0;

/// How long a robot must be stuck before it breaks a deadlock, s.
pub const STUCK_TIME: f64 = 1.0;

/// In an *encounter* (the nominal closes on a neighbour that comes toward
/// the robot, its point at 1 cm/s or more, faster than their barrier
/// allows: that neighbour's row broken by the nominal, with `a·x₀ < 0`),
/// a robot counts as stuck while less than this share of the point motion
/// its nominal asks for survives (elsewhere, half), and starts breaking at
/// once (elsewhere after [`STUCK_TIME`]): the right-hand rule of dense
/// symmetric encounters, applied while the robots still have room to
/// slide past each other rather than after they have closed into a ring
/// at the radius (issue trust2, item 4: 8 to 16 robots swapping across a
/// circle, `docs/safety.md`).
pub const ENCOUNTER_SHARE: f64 = 0.9;

/// How far the desired point motion is turned clockwise while breaking a
/// deadlock, rad.
pub const BIAS_ANGLE: f64 = std::f64::consts::FRAC_PI_4;

/// The window over which a robot its filter holds must bring its tracking
/// error ‖e‖ down by [`PROGRESS_FRACTION`], s: five time constants of a
/// law with `ke = 1/s` (a free robot's ‖e‖ falls by `e^{-5}` in it), and
/// long enough to get round a neighbour (0.3 m radius half round at 0.2 m/s
/// takes about 2.4 s, ‖e‖ rising meanwhile).
pub const PROGRESS_WINDOW: f64 = 5.0;

/// The fraction by which ‖e‖ must fall over [`PROGRESS_WINDOW`] while the
/// filter holds a robot: 10 %.
pub const PROGRESS_FRACTION: f64 = 0.1;

/// Below this ‖e‖ (m) the robot is at its slot (the settling tolerance of
/// `summary.json`) and no progress is asked of it.
pub const PROGRESS_FLOOR: f64 = 0.01;

/// Deadlock monitor state.
#[derive(Debug, Clone, Copy, PartialEq)]
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
    /// The law's tracking error ‖e‖ at the coming call, m (NaN: not told,
    /// no progress test).
    error: f64,
    /// The progress test's reference: ‖e‖ (m) and since when (s).
    progress: Option<(f64, f64)>,
    /// How far (m) the point has moved since the reference, relative to
    /// the neighbour or obstacle nearest it at each call, and over ground.
    path: f64,
    moved: f64,
    /// Windows in a row without progress (reset by progress): the turn a
    /// break the progress test starts takes, so that a robot whose break
    /// ended (its nominal free for an instant) and that fell back into the
    /// same ride does not try the same turn again.
    stalls: u8,
    /// Whether the break was started by the progress test.
    by_progress: bool,
}

impl Default for Deadlock {
    fn default() -> Deadlock {
        Deadlock {
            stuck_since: None,
            breaking: false,
            turns: 0,
            still_since: None,
            breaks: 0,
            last: None,
            now: 0.0,
            error: f64::NAN,
            progress: None,
            path: 0.0,
            moved: 0.0,
            stalls: 0,
            by_progress: false,
        }
    }
}

impl Deadlock {
    /// Whether the filter holds the robot: it changed the command at the
    /// last call or at any call within [`DEADLOCK_MEMORY`] before it.
    pub(super) fn held(&self) -> bool {
        self.last.is_some_and(|t| self.now - t <= DEADLOCK_MEMORY)
    }

    /// Whether the break under way was started by the progress test.
    pub(super) fn by_progress(&self) -> bool {
        self.by_progress
    }

    /// How many deadlocks it has started breaking.
    pub(super) fn breaks(&self) -> u64 {
        self.breaks
    }

    /// The law's tracking error ‖e‖ (m) at the coming call (NaN: unknown).
    pub(super) fn set_error(&mut self, error: f64) {
        self.error = error;
    }

    /// A call at `t` where the nominal satisfied every constraint: not
    /// stuck, not breaking.
    pub(super) fn free(&mut self, t: f64) {
        self.now = t;
        self.stuck_since = None;
        self.end_break();
    }

    /// The robot, breaking, is clear of what held it (its unturned nominal
    /// keeps nearly all of its motion): the break ends, as when the nominal
    /// is free.
    pub(super) fn end_break(&mut self) {
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

    /// After the filter acted at `t`: whether the robot was `stuck`, whether
    /// it stood `still` (the filtered point motion next to nothing of what
    /// the nominal asks), and whether it is in an `encounter` (its nominal
    /// closes on an oncoming neighbour faster than the barrier allows,
    /// [`ENCOUNTER_SHARE`]); it starts breaking a deadlock after
    /// [`STUCK_TIME`] stuck, at once in an encounter. Breaking, a robot
    /// that stands still for [`STUCK_TIME`] tries the next turn of [`bias`] (left, then right and
    /// left by more): the right turn can point the desired motion where
    /// nothing is allowed (a torque robot at rest on a post's barrier,
    /// heading past its left side, may not reverse, and its right-turned
    /// desire pointed into the post, so the QP answered zero for ever),
    /// while some turn always has a part the rows allow, which moves it.
    ///
    /// Progress: while the filter keeps acting (no gap over [`STUCK_TIME`]
    /// between its calls) and ‖e‖ is at least [`PROGRESS_FLOOR`], ‖e‖ must
    /// fall to `1 − `[`PROGRESS_FRACTION`] of its reference within
    /// [`PROGRESS_WINDOW`], or the point must move, relative to the
    /// neighbour or obstacle nearest it (`speeds[0]`, m/s), by
    /// [`PROGRESS_FRACTION`] of that reference (going round a post or past a
    /// neighbour, ‖e‖ grows), or stand (moving over ground, `speeds[1]`,
    /// less than that: the still test's case, a jam); if so, a new window
    /// starts; if it only moves along with what holds it, the robot starts
    /// breaking a deadlock, or, breaking one, tries the next
    /// turn, and the window starts again. A break it starts takes the turn
    /// after the one the last window without progress tried (a break ends
    /// when the nominal is free for an instant, and the robot can fall back
    /// into the same ride). The rows are never relaxed: only
    /// the desired motion given to the QP turns.
    pub(super) fn record(
        &mut self,
        t: f64,
        stuck: bool,
        still: bool,
        encounter: bool,
        speeds: [f64; 2],
    ) {
        self.progress(t, speeds);
        if stuck {
            let since = *self.stuck_since.get_or_insert(t);
            // Keep right at once in an encounter: a robot that waits lets the
            // crowd close into a ring at the radius, which a robot that may
            // not reverse (a torque robot's envelope) cannot leave.
            let wait = if encounter { 0.0 } else { STUCK_TIME };
            if !self.breaking && t - since >= wait {
                self.breaking = true;
                self.breaks += 1;
                self.by_progress = false;
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

    /// The progress test of [`Deadlock::record`] at an acting call at `t`,
    /// the point moving at `relative` (m/s) relative to the neighbour or
    /// obstacle nearest it and at `speed` (m/s) over ground.
    fn progress(&mut self, t: f64, [relative, speed]: [f64; 2]) {
        let e = self.error;
        let held_on = self.last.filter(|&l| t - l <= STUCK_TIME);
        if !(e.is_finite() && e >= PROGRESS_FLOOR) {
            // No window (at the slot, or not told): nothing measured is kept
            // (the next window starts clean; a window whose ‖e‖ fell below
            // the floor kept its motion here, which the property test
            // below found).
            self.progress = None;
            self.stalls = 0;
            self.path = 0.0;
            self.moved = 0.0;
            return;
        }
        match (self.progress, held_on) {
            (Some((reference, since)), Some(last)) => {
                if relative.is_finite() {
                    self.path += relative * (t - last);
                }
                self.moved += speed * (t - last);
                if e <= (1.0 - PROGRESS_FRACTION) * reference {
                    self.restart(e, t);
                    self.stalls = 0;
                } else if t - since >= PROGRESS_WINDOW
                    && (self.path >= PROGRESS_FRACTION * reference
                        || self.moved < PROGRESS_FRACTION * reference)
                {
                    // It moves round what holds it (a post, a neighbour it
                    // passes; ‖e‖ may grow meanwhile), or it stands (the
                    // still test's case, a jam): a new window.
                    self.restart(e, t);
                } else if t - since >= PROGRESS_WINDOW {
                    if self.breaking {
                        self.turns = (self.turns + 1) % BIASES;
                        self.still_since = None;
                    } else {
                        self.breaking = true;
                        self.breaks += 1;
                        self.by_progress = true;
                        self.turns = self.stalls % BIASES;
                    }
                    self.stalls = (self.stalls + 1) % BIASES;
                    self.restart(e, t);
                }
            }
            _ => {
                self.restart(e, t);
                self.stalls = 0;
            }
        }
    }

    /// Starts a new progress window at `t` with reference ‖e‖ = `e`: the
    /// motion measured in the last one (`path` and `moved`) is forgotten, so
    /// each window's verdict rests on its own motion only (a window that
    /// ended on progress must not lend its ground motion to the next, where
    /// a robot standing still would count as riding along).
    fn restart(&mut self, e: f64, t: f64) {
        self.progress = Some((e, t));
        self.path = 0.0;
        self.moved = 0.0;
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

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// Acting calls every 0.1 s from `t0` for `seconds`, the point moving at
    /// `speed` over ground and not relative to what holds it, with ‖e‖ =
    /// `error` (`stuck` and `still` false: only the progress test acts).
    fn ride(d: &mut Deadlock, t0: f64, seconds: f64, error: f64, speed: f64) -> f64 {
        let steps = (seconds / 0.1).round() as u64;
        let mut t = t0;
        for k in 1..=steps {
            t = t0 + k as f64 * 0.1;
            d.set_error(error);
            d.record(t, false, false, false, [0.0, speed]);
        }
        t
    }

    /// The case of issue 46: a window that ends on progress (‖e‖ fell by
    /// more than 10 %) after the point moved over ground, then a robot that
    /// stands: the new window sees no motion (a jam, the still test's case)
    /// and starts no break. Before the fix the first window's `moved`
    /// carried over and the standing robot counted as riding along.
    #[test]
    fn a_window_that_ends_on_progress_lends_no_motion_to_the_next() {
        let mut d = Deadlock::default();
        let t = ride(&mut d, 0.0, 4.0, 1.0, 0.5);
        // ‖e‖ falls by 20 %: progress, a new window.
        let t = ride(&mut d, t, 0.1, 0.8, 0.0);
        ride(&mut d, t, PROGRESS_WINDOW + 1.0, 0.8, 0.0);
        assert_eq!(d.breaks(), 0, "{d:?}");
        assert_eq!(d.moved, 0.0, "standing since the window began: {d:?}");
    }

    proptest! {
        /// Whatever the point did before a window that ended on progress
        /// (over-ground speed, how long), the next window starts from a
        /// clean state: a robot standing in it starts no break, and what it
        /// measured is only that window's motion.
        #[test]
        fn each_progress_window_starts_from_a_clean_state(
            speed in 0.0f64..2.0,
            before in 0.2f64..4.9,
            error in 0.05f64..5.0,
            drop in 0.11f64..0.9,
            standing in 0.0f64..1.0,
        ) {
            let mut d = Deadlock::default();
            let t = ride(&mut d, 0.0, before, error, speed);
            let e = error * (1.0 - drop);
            let t = ride(&mut d, t, 0.1, e, 0.0);
            prop_assert_eq!(d.moved, 0.0, "a new window forgets the last one's motion");
            // Standing (over-ground motion under the fraction of ‖e‖ that
            // counts as moving) for a whole window: a jam, no break.
            let slow = standing * PROGRESS_FRACTION * e / (PROGRESS_WINDOW + 1.0);
            ride(&mut d, t, PROGRESS_WINDOW + 0.5, e, slow);
            prop_assert_eq!(d.breaks(), 0, "{:?}", d);
        }
    }
}
