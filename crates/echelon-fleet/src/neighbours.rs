//! What a fleet robot knows of the other robots for its safety filter
//! (`docs/safety.md`, "In the fleet"): the latest state each one published on
//! `echelon/<fleet>/robot/<k>/state`, kept in one fixed slot per agent (no
//! allocation per message), and the neighbour list built from it at each
//! control step.
//!
//! ## Freshness and the stale policy
//!
//! A neighbour's entry is *fresh* while its last message arrived at most
//! `timeout` ago (the robot's local clock, so a neighbour that is not synced
//! yet, whose states carry `t = 0`, is still seen). A fresh neighbour is
//! brought to the robot's instant (its pose advanced along the arc of its
//! `(v, ω)`, its speeds by its `(v̇, ω̇)`, over the age of its sample, at most
//! `timeout`) and enters the filter with its measured motion, cooperative if
//! the scenario gives it a filter, **its sample is at most `lag` old** (two
//! control periods) **and it is following** (its link `tracking`,
//! `extrapolating` or `stopping`): a robot that says it is `stopped` (a
//! fleet stop, its base's hazard) or `waiting` (no leader, no odometry)
//! commands zero, takes no share of any barrier, and is avoided as a
//! braking obstacle with its measured motion. The pair split (each robot takes half of the pair
//! constraint) holds only if both act on the same situation at about the same
//! instant; a neighbour whose last state is older than that has not acted on
//! anything since (its process stalled, or its messages are late) while its
//! plant keeps moving under its held command, so this robot keeps the whole
//! pair constraint against the neighbour's extrapolated motion.
//!
//! A neighbour whose stream went stale **while its last point was within
//! `range`**:
//!
//! 1. for `hold` more seconds enters as a *non-cooperative, stopped* disc at
//!    its last point: the robot alone keeps the whole pair constraint, against
//!    a neighbour assumed at rest (a neighbour that lost its own leader or
//!    odometry, or whose process died, commands zero: the project's rule);
//! 2. after that, if it is still stale, the robot **brakes** (zero velocity,
//!    or the filter's braking torques) until the neighbour is heard again:
//!    its position is then unknown, and standing still is the one command
//!    that cannot drive the robot into it.
//!
//! A stale neighbour whose last point was beyond `range` is ignored (as a
//! fresh one would be). Each fresh → stale transition within range is counted
//! ([`NeighbourTable::stale_events`]).

use echelon::agent::Sight;
use echelon::model::State;
use echelon::safety::{Neighbour, point, uncertainty_margin};

use crate::wire::{Header, LinkStatus, RobotState};

/// How long a stale neighbour within range is taken as stopped at its last
/// point before the robot brakes, fleet s.
pub const STALE_HOLD: f64 = 0.5;

/// How old (in control periods) a fresh neighbour's sample may be and the
/// neighbour still be trusted to take its half of a pair constraint.
pub const LAG_PERIODS: f64 = 2.0;

/// One agent's slot.
#[derive(Debug, Clone, Copy, Default)]
struct Entry {
    /// Whether anything was received from it.
    known: bool,
    /// Its last accepted state.
    state: RobotState,
    /// Its stream: the source and sequence number of the last accepted message.
    source: u32,
    seq: u64,
    /// Local time of receipt, s.
    received: f64,
    /// Whether it was stale within range at the last build.
    stale: bool,
}

/// The latest state of every other robot of the fleet.
#[derive(Debug, Clone)]
pub struct NeighbourTable {
    /// This robot's agent number, from 1.
    me: u32,
    /// `L` of every agent (index agent − 1).
    l: Vec<f64>,
    /// Whether every agent runs the filter.
    cooperative: Vec<bool>,
    entries: Vec<Entry>,
    list: Vec<Neighbour>,
    /// A message older than this (on the local clock) is stale, s.
    timeout: f64,
    /// How long a stale neighbour within range is taken as stopped, s.
    hold: f64,
    /// A fresh neighbour whose sample is older than this (fleet time) is
    /// taken as non-cooperative, s.
    lag: f64,
    /// Fresh neighbours taken as non-cooperative for their sample's age.
    lagging: u64,
    stale_events: u64,
    refused: u64,
}

impl NeighbourTable {
    /// The table of agent `me` (from 1) in a fleet whose agents have points
    /// `l[k − 1]` ahead and filter (`cooperative[k − 1]`); `timeout`, `hold`
    /// and `lag` as in the module's docs.
    pub fn new(
        me: u32,
        l: Vec<f64>,
        cooperative: Vec<bool>,
        timeout: f64,
        hold: f64,
        lag: f64,
    ) -> Self {
        let n = l.len();
        NeighbourTable {
            me,
            l,
            cooperative,
            entries: vec![Entry::default(); n],
            list: Vec::with_capacity(n),
            timeout,
            hold,
            lag,
            lagging: 0,
            stale_events: 0,
            refused: 0,
        }
    }

    /// Takes a decoded state message that arrived at local time `now`; its
    /// own are ignored, unknown agents and older messages of the same stream
    /// are refused (counted).
    pub fn on_state(&mut self, h: Header, s: &RobotState, now: f64) {
        if s.agent == self.me {
            return;
        }
        let Some(e) = (s.agent as usize)
            .checked_sub(1)
            .and_then(|i| self.entries.get_mut(i))
        else {
            self.refused += 1;
            return;
        };
        if e.known && e.source == h.source && h.seq <= e.seq {
            self.refused += 1;
            return;
        }
        *e = Entry {
            known: true,
            state: *s,
            source: h.source,
            seq: h.seq,
            received: now,
            stale: e.stale,
        };
    }

    /// Neighbour stale events: a neighbour within range whose stream went
    /// stale (once per episode).
    pub fn stale_events(&self) -> u64 {
        self.stale_events
    }

    /// Neighbour entries (one per neighbour per step) taken as
    /// non-cooperative because their sample was older than `lag`.
    pub fn lagging(&self) -> u64 {
        self.lagging
    }

    /// Counts a message refused by the caller (malformed, not a state).
    pub fn refuse(&mut self) {
        self.refused += 1;
    }

    /// Messages refused (own, unknown agent, reordered or duplicated).
    pub fn refused(&self) -> u64 {
        self.refused
    }

    /// The neighbours for a control step at local time `local` (fleet time
    /// `t`) of a robot whose point is `p`, seeing `range` far, whose
    /// position estimate has standard deviation `sigma` (each pair's radius
    /// widened by [`uncertainty_margin`] of the two).
    pub fn build(&mut self, local: f64, t: f64, p: [f64; 2], range: f64, sigma: f64) -> Sight<'_> {
        self.list.clear();
        let mut brake = false;
        for (i, e) in self.entries.iter_mut().enumerate() {
            if !e.known || i + 1 == self.me as usize {
                continue;
            }
            let l = self.l[i];
            let age = local - e.received;
            if age <= self.timeout {
                e.stale = false;
                let dt = if e.state.link == LinkStatus::Waiting {
                    0.0
                } else {
                    (t - e.state.t).clamp(0.0, self.timeout)
                };
                // A robot that halts (stopped, held by a watchdog, waiting)
                // commands zero: it takes no half of the pair constraint,
                // and it is an obstacle at rest where it says it is, not
                // one moving on at the speed it reported (a held robot's
                // odometry may be frozen at its cruising speed).
                let acting = !matches!(
                    e.state.link,
                    LinkStatus::Stopped | LinkStatus::Held | LinkStatus::Waiting
                );
                if !acting {
                    self.list.push(at_rest(
                        point(&e.state.state, l),
                        uncertainty_margin(sigma, e.state.sigma),
                    ));
                    continue;
                }
                let (s, dv) = advance(&e.state, dt);
                let lagging = dt > self.lag;
                self.lagging += u64::from(lagging && self.cooperative[i]);
                // A torque robot's `dv` is its acceleration under the
                // command it applied at that tick: a torque robot takes over
                // what it fell short of its half (`Neighbour::sharing`).
                let cooperative = self.cooperative[i] && !lagging;
                let torque = e.state.velocity.is_none();
                self.list.push(
                    Neighbour::of_state(&s, l, Some(dv), cooperative)
                        .sharing(torque)
                        .with_margin(uncertainty_margin(sigma, e.state.sigma)),
                );
                continue;
            }
            let q = point(&e.state.state, l);
            if (q[0] - p[0]).hypot(q[1] - p[1]) > range {
                e.stale = false;
                continue;
            }
            if !e.stale {
                e.stale = true;
                self.stale_events += 1;
            }
            if age > self.timeout + self.hold {
                brake = true;
            }
            self.list
                .push(at_rest(q, uncertainty_margin(sigma, e.state.sigma)));
        }
        if brake {
            Sight::Stale
        } else {
            Sight::Neighbours(&self.list)
        }
    }
}

/// A neighbour taken as an obstacle at rest at its point `p`, with no
/// share of the barrier, its radius widened by `margin`: a halted robot,
/// or one whose stream went stale.
fn at_rest(p: [f64; 2], margin: f64) -> Neighbour {
    Neighbour {
        p,
        cooperative: false,
        margin,
        ..Neighbour::default()
    }
}

/// A neighbour's state `dt` after its sample: the arc of constant `(v, ω)`,
/// speeds advanced by `(v̇, ω̇)`; and `(v̇, ω̇)`.
fn advance(s: &RobotState, dt: f64) -> (State, [f64; 2]) {
    let x = &s.state;
    let dth = x.omega * dt;
    // sinc-weighted chord of the arc: exact for constant (v, ω).
    let (sin, cos) = (x.theta + 0.5 * dth).sin_cos();
    let chord = if dth.abs() < 1e-9 {
        x.v * dt
    } else {
        2.0 * x.v / x.omega * (0.5 * dth).sin()
    };
    (
        State {
            x: x.x + chord * cos,
            y: x.y + chord * sin,
            theta: x.theta + dth,
            v: x.v + s.dv * dt,
            omega: x.omega + s.domega * dt,
        },
        [s.dv, s.domega],
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    const TIMEOUT: f64 = 0.2;
    const LAG: f64 = 0.02;

    fn table() -> NeighbourTable {
        NeighbourTable::new(
            1,
            vec![0.05; 3],
            vec![true, true, false],
            TIMEOUT,
            STALE_HOLD,
            LAG,
        )
    }

    fn msg(agent: u32, seq: u64, t: f64, x: f64, v: f64) -> (Header, RobotState) {
        (
            Header { source: 7, seq },
            RobotState {
                t,
                agent,
                link: LinkStatus::Tracking,
                state: State {
                    x,
                    v,
                    ..State::default()
                },
                ..RobotState::default()
            },
        )
    }

    fn list(v: Sight<'_>) -> Vec<Neighbour> {
        match v {
            Sight::Neighbours(n) => n.to_vec(),
            Sight::Stale => panic!("braking"),
        }
    }

    /// Each pair's radius is widened by both robots' published `σ`
    /// (`uncertainty_margin`), fresh or stale.
    #[test]
    fn uncertain_neighbours_get_a_wider_radius() {
        let mut n = table();
        let (h, s) = msg(2, 0, 1.0, 1.0, 0.5);
        n.on_state(h, &RobotState { sigma: 0.02, ..s }, 10.0);
        let (h, s) = msg(3, 0, 1.0, -1.0, 0.0);
        n.on_state(h, &s, 10.0);
        let got = list(n.build(10.01, 1.01, [0.0, 0.0], 5.0, 0.01));
        assert!(
            (got[0].margin - 3.0 * (0.01 + 0.02)).abs() < 1e-15,
            "{got:?}"
        );
        assert!((got[1].margin - 3.0 * 0.01).abs() < 1e-15, "{got:?}");
        // Stale within range (before the hold): still widened.
        let got = list(n.build(10.0 + TIMEOUT + 0.01, 1.3, [0.0, 0.0], 5.0, 0.0));
        assert!(
            (got[0].margin - 0.06).abs() < 1e-15 && got[1].margin == 0.0,
            "{got:?}"
        );
    }

    #[test]
    fn fresh_neighbours_are_advanced_to_now_and_keep_their_cooperation() {
        let mut n = table();
        let (h, s) = msg(2, 0, 1.0, 1.0, 0.5);
        n.on_state(h, &s, 10.0);
        let (h, s) = msg(3, 0, 1.0, -1.0, 0.0);
        n.on_state(h, &s, 10.0);
        // 10 ms later (both clocks): agent 2 moved 5 mm along x; within the
        // lag it still takes its half of the pair constraint.
        let got = list(n.build(10.01, 1.01, [0.0, 0.0], 5.0, 0.0));
        assert_eq!(got.len(), 2);
        assert!(
            (got[0].p[0] - (1.0 + 0.05 + 0.005)).abs() < 1e-12,
            "{got:?}"
        );
        assert!((got[0].dp[0] - 0.5).abs() < 1e-12);
        assert!(got[0].cooperative);
        assert!(!got[1].cooperative);
        assert_eq!(n.lagging(), 0);
        // 0.1 s later, nothing new heard: advanced 5 cm, and no longer trusted
        // to act (its sample is older than the lag): non-cooperative.
        let got = list(n.build(10.1, 1.1, [0.0, 0.0], 5.0, 0.0));
        assert!((got[0].p[0] - (1.0 + 0.05 + 0.05)).abs() < 1e-12, "{got:?}");
        assert!(!got[0].cooperative && !got[1].cooperative);
        assert_eq!(n.lagging(), 1);
        assert_eq!(n.stale_events(), 0);
    }

    /// A neighbour that says it halts (a fleet stop, its base's hazard, no
    /// leader or odometry) takes no share of the barrier; following again,
    /// it does.
    #[test]
    fn a_halted_neighbour_is_not_cooperative() {
        for (link, cooperates) in [
            (LinkStatus::Tracking, true),
            (LinkStatus::Extrapolating, true),
            (LinkStatus::Stopping, true),
            (LinkStatus::Stopped, false),
            (LinkStatus::Held, false),
            (LinkStatus::Waiting, false),
        ] {
            let mut n = table();
            let (h, s) = msg(2, 0, 1.0, 1.0, 0.2);
            n.on_state(h, &RobotState { link, ..s }, 10.0);
            let got = list(n.build(10.01, 1.01, [0.0, 0.0], 5.0, 0.0));
            assert_eq!(got[0].cooperative, cooperates, "{link:?}");
        }
    }

    #[test]
    fn an_arc_is_advanced_exactly() {
        let s = RobotState {
            state: State {
                v: 1.0,
                omega: 1.0,
                ..State::default()
            },
            ..RobotState::default()
        };
        let (a, _) = advance(&s, std::f64::consts::FRAC_PI_2);
        // A quarter of the unit circle centred at (0, 1).
        assert!(
            (a.x - 1.0).abs() < 1e-12 && (a.y - 1.0).abs() < 1e-12,
            "{a:?}"
        );
    }

    #[test]
    fn own_messages_are_ignored_unknown_and_reordered_ones_refused() {
        let mut n = table();
        let (h, s) = msg(1, 0, 0.0, 3.0, 0.0);
        n.on_state(h, &s, 0.0);
        let (h, s) = msg(4, 0, 0.0, 3.0, 0.0);
        n.on_state(h, &s, 0.0);
        let (h, s) = msg(2, 5, 0.0, 1.0, 0.0);
        n.on_state(h, &s, 0.0);
        let (h, s) = msg(2, 4, 0.0, 2.0, 0.0);
        n.on_state(h, &s, 0.0);
        assert_eq!(n.refused(), 2);
        let got = list(n.build(0.0, 0.0, [0.0, 0.0], 5.0, 0.0));
        assert_eq!(got.len(), 1);
        assert!((got[0].p[0] - 1.05).abs() < 1e-12);
        // A restarted neighbour (new source) starts again from seq 0.
        let (mut h, s) = msg(2, 0, 0.0, 2.0, 0.0);
        h.source = 8;
        n.on_state(h, &s, 0.0);
        let got = list(n.build(0.0, 0.0, [0.0, 0.0], 5.0, 0.0));
        assert!((got[0].p[0] - 2.05).abs() < 1e-12);
    }

    #[test]
    fn a_stale_neighbour_in_range_is_held_stopped_then_brakes_then_recovers() {
        let mut n = table();
        let (h, s) = msg(2, 0, 1.0, 1.0, 0.5);
        n.on_state(h, &s, 10.0);
        // Stale (older than the timeout): non-cooperative, at rest, at its
        // last point (not advanced).
        let t = 10.0 + TIMEOUT + 0.1;
        let got = list(n.build(t, 1.3, [0.0, 0.0], 1.5, 0.0));
        assert_eq!(got.len(), 1);
        assert_eq!(got[0].p, [1.05, 0.0]);
        assert_eq!((got[0].dp, got[0].cooperative), ([0.0; 2], false));
        assert_eq!(n.stale_events(), 1);
        // Still within the hold: one episode, counted once.
        let _ = list(n.build(t + STALE_HOLD - 0.2, 1.6, [0.0, 0.0], 1.5, 0.0));
        assert_eq!(n.stale_events(), 1);
        // Past the hold: brake.
        assert_eq!(
            n.build(
                10.0 + TIMEOUT + STALE_HOLD + 0.01,
                1.8,
                [0.0, 0.0],
                1.5,
                0.0
            ),
            Sight::Stale
        );
        // Heard again: fresh, cooperative; a later loss is a new episode.
        let (h, s) = msg(2, 1, 2.0, 1.0, 0.0);
        n.on_state(h, &s, 11.0);
        assert!(list(n.build(11.0, 2.0, [0.0, 0.0], 1.5, 0.0))[0].cooperative);
        let _ = n.build(11.0 + TIMEOUT + 0.01, 2.3, [0.0, 0.0], 1.5, 0.0);
        assert_eq!(n.stale_events(), 2);
    }

    #[test]
    fn a_stale_neighbour_out_of_range_is_ignored() {
        let mut n = table();
        let (h, s) = msg(3, 0, 0.0, 4.0, 0.0);
        n.on_state(h, &s, 0.0);
        // In range while fresh: seen (the filter itself ignores it beyond range).
        assert_eq!(list(n.build(0.1, 0.1, [0.0, 0.0], 1.5, 0.0)).len(), 1);
        // Stale beyond range, however long: neither seen, nor counted, nor braking.
        assert!(list(n.build(100.0, 100.0, [0.0, 0.0], 1.5, 0.0)).is_empty());
        assert_eq!(n.stale_events(), 0);
        // Never heard of: nothing.
        assert!(list(table().build(0.0, 0.0, [0.0, 0.0], 1.5, 0.0)).is_empty());
    }
}
