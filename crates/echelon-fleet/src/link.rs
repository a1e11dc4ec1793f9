//! A robot's link to its leader: which messages are accepted (sequence,
//! staleness, counters) and what leader motion the law sees, fresh or lost
//! (the link-loss policy).

use serde::{Deserialize, Serialize};

use echelon::control::LeaderMotion;
use echelon::guard::Bounds;
use echelon::scenario::{LinkLoss, LinkPolicy};

use crate::wire::{Header, LinkStatus};

/// What a receiver counts, per stream. Every message that reaches the process
/// lands in exactly one of `accepted`, `malformed`, `wrong_version`, `foreign`,
/// `injected_loss`, `injected_outage`, `stale`, `reordered` (or is still
/// delayed when the process stops).
#[derive(
    Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize, schemars::JsonSchema,
)]
#[serde(deny_unknown_fields)]
pub struct Counters {
    /// Samples that reached the process on the stream's key.
    pub received: u64,
    /// Used by the controller.
    pub accepted: u64,
    /// Undecodable: wrong length, magic, kind, non-finite number; or a
    /// sample no robot could follow ([`LeaderSample::within`]).
    pub malformed: u64,
    /// Another format version.
    pub wrong_version: u64,
    /// Well-formed but not of this stream (a state on the reference key,
    /// another agent's number…), or a leader robot's state while it waits
    /// or a watchdog holds it (not a pose to follow).
    pub foreign: u64,
    /// Dropped by `--loss`.
    pub injected_loss: u64,
    /// Dropped by `--outage`.
    pub injected_outage: u64,
    /// Older than `stale_after` on delivery (or as far in the future).
    pub stale: u64,
    /// Sequence number not above the last accepted one of the same source (duplicates too).
    pub reordered: u64,
    /// A new source appeared (the sender restarted).
    pub restarts: u64,
    /// Times the link went from fresh to lost.
    pub link_losses: u64,
}

/// Why a decoded message was not accepted.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Refusal {
    /// Too old (or too far in the future).
    Stale,
    /// Not newer than the last accepted message of its source.
    Reordered,
}

/// Sequence and staleness checks for one stream.
#[derive(Debug, Clone)]
pub struct StreamTracker {
    source: Option<u32>,
    last_seq: u64,
    stale_after: f64,
    /// The stream's counters.
    pub counters: Counters,
}

impl StreamTracker {
    /// A tracker dropping messages older than `stale_after` s on delivery.
    pub fn new(stale_after: f64) -> Self {
        StreamTracker {
            source: None,
            last_seq: 0,
            stale_after,
            counters: Counters::default(),
        }
    }

    /// Whether `h` comes from a source other than the current one (a restart,
    /// or the first message).
    pub fn is_new_source(&self, h: &Header) -> bool {
        self.source != Some(h.source)
    }

    /// Checks a decoded message sent at `t` and delivered at fleet time `now`;
    /// counts the outcome.
    pub fn check(&mut self, h: Header, t: f64, now: f64) -> Result<(), Refusal> {
        if (now - t).abs() > self.stale_after {
            self.counters.stale += 1;
            return Err(Refusal::Stale);
        }
        if self.source == Some(h.source) {
            if h.seq <= self.last_seq {
                self.counters.reordered += 1;
                return Err(Refusal::Reordered);
            }
        } else {
            if self.source.is_some() {
                self.counters.restarts += 1;
            }
            self.source = Some(h.source);
        }
        self.last_seq = h.seq;
        self.counters.accepted += 1;
        Ok(())
    }
}

/// The last accepted sample of the leader: a reference, or a leader robot's
/// state turned into `p_d, ṗ_d, p̈_d` (`LeaderMotion::of_robot`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LeaderSample {
    /// Sender time, s.
    pub t: f64,
    /// `p_d, ṗ_d, p̈_d` at `t`.
    pub motion: LeaderMotion,
    /// `V_d` (a robot leader's `v`), m/s.
    pub speed: f64,
    /// `ω_d`, rad/s.
    pub turn_rate: f64,
}

/// The largest sender time a sample may carry, s (about 31 years): the
/// first sample sets a robot's clock.
pub const MAX_SAMPLE_TIME: f64 = 1e9;

impl LeaderSample {
    /// Whether this sample is one a robot could follow: its time within
    /// [`MAX_SAMPLE_TIME`]; its position, speeds and turn rate within the
    /// larger of the divergence guard's `bounds` (`[sim] bounds`) and their
    /// defaults ([`Bounds::DEFAULT`]: a robot bounded tighter than its
    /// leader moves diverges, as in the simulator, rather than losing it);
    /// its acceleration within the centripetal one of the largest speed at
    /// the largest turn rate. A finite sample beyond them (a leader 1e308 m
    /// away) overflowed the law and stopped the robot as diverged, on one
    /// message.
    pub fn within(&self, bounds: &Bounds) -> bool {
        let d = Bounds::DEFAULT;
        let (speed, turn_rate, distance) = (
            bounds.speed.max(d.speed),
            bounds.turn_rate.max(d.turn_rate),
            bounds.distance.max(d.distance),
        );
        let norm = |v: [f64; 2]| v[0].hypot(v[1]);
        let m = &self.motion;
        self.t.abs() <= MAX_SAMPLE_TIME
            && norm(m.p) <= distance
            && norm(m.dp) <= speed
            && norm(m.ddp) <= speed * turn_rate
            && self.speed.abs() <= speed
            && self.turn_rate.abs() <= turn_rate
    }
}

/// The leader motion the law should use now.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Predicted {
    /// `p_d, ṗ_d, p̈_d` now.
    pub motion: LeaderMotion,
    /// `V_d` now (for `L_Ycomp`), m/s.
    pub speed: f64,
    /// `ω_d` now, rad/s.
    pub turn_rate: f64,
    /// Fresh, extrapolating or stopping.
    pub status: LinkStatus,
}

/// The motion of a point that starts at `m.p` moving along `ṗ = m.dp` and turns
/// at `turn_rate`, with both speed and turn rate scaled by a profile `f`:
/// after travelling the scaled time `big_f = ∫f`, at scale `f` and `ḟ`.
/// Exact for the circle (eq. 18) and the line.
fn along_arc(m: &LeaderMotion, turn_rate: f64, big_f: f64, f: f64, df: f64) -> LeaderMotion {
    let speed = m.dp[0].hypot(m.dp[1]);
    if speed <= 1e-12 {
        return LeaderMotion {
            p: m.p,
            dp: [0.0, 0.0],
            ddp: [0.0, 0.0],
        };
    }
    let theta0 = m.dp[1].atan2(m.dp[0]);
    let dtheta = turn_rate * big_f;
    let dist = speed * big_f;
    let theta = theta0 + dtheta;
    let (s0, c0) = theta0.sin_cos();
    let (s1, c1) = theta.sin_cos();
    // ∫ [cos, sin](θ0 + ω u) du over the travelled scaled time, times speed.
    let (dx, dy) = if dtheta.abs() < 1e-9 {
        // Second-order expansion avoids 0/0 for a straight line.
        (
            dist * (c0 - 0.5 * dtheta * s0),
            dist * (s0 + 0.5 * dtheta * c0),
        )
    } else {
        let r = dist / dtheta;
        (r * (s1 - s0), r * (c0 - c1))
    };
    LeaderMotion {
        p: [m.p[0] + dx, m.p[1] + dy],
        dp: [f * speed * c1, f * speed * s1],
        ddp: [
            df * speed * c1 - f * f * speed * turn_rate * s1,
            df * speed * s1 + f * f * speed * turn_rate * c1,
        ],
    }
}

/// The `extrapolate` stop profile after the hold: speed scale
/// `f(s) = (1 + cos(π s/T))/2` for `s < T`, then 0, with `T = π V/(2 a)` so the
/// peak deceleration is `a`. Returns `(∫₀ˢ f, f, ḟ)`. Both `f` and `ḟ` are
/// continuous: no jump in `p̈_d` when the stop begins or ends.
fn stop_profile(s: f64, speed: f64, decel: f64) -> (f64, f64, f64) {
    let big_t = std::f64::consts::PI * speed.abs() / (2.0 * decel);
    if big_t <= 0.0 || s >= big_t {
        return (0.5 * big_t, 0.0, 0.0);
    }
    let a = std::f64::consts::PI / big_t;
    (
        0.5 * s + (a * s).sin() / (2.0 * a),
        0.5 * (1.0 + (a * s).cos()),
        -0.5 * a * (a * s).sin(),
    )
}

/// What the law sees at fleet time `now` given the last accepted sample.
///
/// - Fresh (`now − t ≤ timeout`): the sample advanced by its age with its own
///   `ṗ_d`, `p̈_d` (second-order Taylor: the age is a few milliseconds).
/// - Lost, `stop`: the last received position, at rest.
/// - Lost, `extrapolate`: the sample advanced along its arc with its last
///   `V_d`, `ω_d` until `hold` s after `t`, then slowed to rest along the same
///   arc with peak deceleration `decel`.
pub fn predict(sample: &LeaderSample, now: f64, timeout: f64, loss: &LinkLoss) -> Predicted {
    let age = now - sample.t;
    let m = &sample.motion;
    if age <= timeout {
        let tau = age;
        return Predicted {
            motion: LeaderMotion {
                p: [
                    m.p[0] + tau * m.dp[0] + 0.5 * tau * tau * m.ddp[0],
                    m.p[1] + tau * m.dp[1] + 0.5 * tau * tau * m.ddp[1],
                ],
                dp: [m.dp[0] + tau * m.ddp[0], m.dp[1] + tau * m.ddp[1]],
                ddp: m.ddp,
            },
            speed: sample.speed,
            turn_rate: sample.turn_rate,
            status: LinkStatus::Tracking,
        };
    }
    match loss.policy {
        LinkPolicy::Stop => Predicted {
            motion: LeaderMotion {
                p: m.p,
                dp: [0.0, 0.0],
                ddp: [0.0, 0.0],
            },
            speed: 0.0,
            turn_rate: 0.0,
            status: LinkStatus::Stopping,
        },
        LinkPolicy::Extrapolate => {
            if age <= loss.hold {
                Predicted {
                    motion: along_arc(m, sample.turn_rate, age, 1.0, 0.0),
                    speed: sample.speed,
                    turn_rate: sample.turn_rate,
                    status: LinkStatus::Extrapolating,
                }
            } else {
                let speed = m.dp[0].hypot(m.dp[1]);
                let (big_f, f, df) = stop_profile(age - loss.hold, speed, loss.decel);
                Predicted {
                    motion: along_arc(m, sample.turn_rate, loss.hold + big_f, f, df),
                    speed: f * sample.speed,
                    turn_rate: f * sample.turn_rate,
                    status: LinkStatus::Stopping,
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::circle;
    use echelon::reference::{Circle, Order, Trajectory};

    fn sample_of(c: &Circle, t: f64) -> LeaderSample {
        let j = c.eval(t, Order::Two);
        LeaderSample {
            t,
            motion: LeaderMotion::of_jet(&j),
            speed: j.speed(),
            turn_rate: j.turn_rate(),
        }
    }

    /// `extrapolate` for `hold` seconds, then stop decelerating at `decel`.
    const fn extrapolate(hold: f64, decel: f64) -> LinkLoss {
        LinkLoss {
            policy: LinkPolicy::Extrapolate,
            hold,
            decel,
        }
    }

    fn close(a: [f64; 2], b: [f64; 2], tol: f64) -> bool {
        (a[0] - b[0]).abs() < tol && (a[1] - b[1]).abs() < tol
    }

    const EXTRAPOLATE: LinkLoss = extrapolate(5.0, 0.1);

    #[test]
    fn extrapolation_of_a_circle_is_the_circle() {
        // Eq. 18: advancing with the last V_d, ω_d is exact on a circle.
        let c = circle([1.0, -2.0], 0.3, 0.4, 0.25);
        let s = sample_of(&c, 2.0);
        for now in [2.5, 3.0, 6.9] {
            let p = predict(&s, now, 0.2, &EXTRAPOLATE);
            let want = c.eval(now, Order::Two);
            assert_eq!(p.status, LinkStatus::Extrapolating);
            assert!(
                close(p.motion.p, want.p, 1e-12),
                "{:?} {:?}",
                p.motion.p,
                want.p
            );
            assert!(close(p.motion.dp, want.dp, 1e-12));
            assert!(close(p.motion.ddp, want.ddp, 1e-12));
        }
    }

    #[test]
    fn fresh_samples_are_advanced_by_their_age() {
        let c = circle([0.0, 0.0], 0.0, 0.5, 0.5);
        let s = sample_of(&c, 1.0);
        let p = predict(&s, 1.01, 0.2, &EXTRAPOLATE);
        assert_eq!(p.status, LinkStatus::Tracking);
        // Taylor to second order: error O(τ³ V ω²) ≈ 1e-7.
        assert!(close(p.motion.p, c.eval(1.01, Order::Two).p, 1e-6));
    }

    #[test]
    fn stop_holds_the_last_position() {
        let c = circle([0.0, 0.0], 0.0, 0.5, 0.5);
        let s = sample_of(&c, 1.0);
        let stop = LinkLoss {
            policy: LinkPolicy::Stop,
            ..EXTRAPOLATE
        };
        let p = predict(&s, 1.5, 0.2, &stop);
        assert_eq!(p.status, LinkStatus::Stopping);
        assert_eq!(p.motion.p, s.motion.p);
        assert_eq!(p.motion.dp, [0.0, 0.0]);
        assert_eq!(p.speed, 0.0);
    }

    #[test]
    fn extrapolation_decelerates_smoothly_to_rest() {
        let c = circle([0.0, 0.0], 0.0, 0.4, 0.1);
        let s = sample_of(&c, 0.0);
        let loss = extrapolate(1.0, 0.2);
        // T = π V / (2a) = π 0.4 / 0.4 = π s.
        let big_t = std::f64::consts::PI;
        let mut last = predict(&s, 1.0, 0.2, &loss);
        let dt = 1e-3;
        let mut peak_decel: f64 = 0.0;
        let mut t = 1.0 + dt;
        while t < 1.0 + big_t + 1.0 {
            let p = predict(&s, t, 0.2, &loss);
            let speed = p.motion.dp[0].hypot(p.motion.dp[1]);
            let last_speed = last.motion.dp[0].hypot(last.motion.dp[1]);
            // Speed never increases, position moves continuously.
            assert!(speed <= last_speed + 1e-12);
            let step = (p.motion.p[0] - last.motion.p[0]).hypot(p.motion.p[1] - last.motion.p[1]);
            assert!(step <= 0.4 * dt + 1e-9);
            // ṗ is the derivative of p (central difference).
            peak_decel = peak_decel.max((last_speed - speed) / dt);
            last = p;
            t += dt;
        }
        assert!((peak_decel - 0.2).abs() < 1e-3, "{peak_decel}");
        assert_eq!(last.motion.dp, [0.0, 0.0]);
        assert_eq!(last.status, LinkStatus::Stopping);
        // Rest point: V (hold + T/2) along the circle of radius V/ω = 4 m.
        let want = c.eval(1.0 + 0.5 * big_t, Order::Two).p;
        assert!(
            close(last.motion.p, want, 1e-9),
            "{:?} {want:?}",
            last.motion.p
        );
    }

    #[test]
    fn velocity_is_the_derivative_of_position_while_stopping() {
        let c = circle([0.0, 0.0], 0.3, 0.4, 0.1);
        let s = sample_of(&c, 0.0);
        let loss = extrapolate(0.5, 0.2);
        for t in [0.7, 1.3, 2.0, 3.1] {
            let h = 1e-5;
            let a = predict(&s, t - h, 0.2, &loss).motion;
            let b = predict(&s, t + h, 0.2, &loss).motion;
            let m = predict(&s, t, 0.2, &loss).motion;
            for k in 0..2 {
                assert!(((b.p[k] - a.p[k]) / (2.0 * h) - m.dp[k]).abs() < 1e-7);
                assert!(((b.dp[k] - a.dp[k]) / (2.0 * h) - m.ddp[k]).abs() < 1e-6);
            }
        }
    }

    #[test]
    fn tracker_drops_stale_reordered_and_counts_restarts() {
        let mut tr = StreamTracker::new(0.5);
        let h = |source, seq| Header { source, seq };
        assert_eq!(tr.check(h(1, 0), 0.0, 0.0), Ok(()));
        assert_eq!(tr.check(h(1, 2), 0.1, 0.1), Ok(()));
        assert_eq!(tr.check(h(1, 1), 0.05, 0.1), Err(Refusal::Reordered));
        assert_eq!(tr.check(h(1, 2), 0.1, 0.1), Err(Refusal::Reordered));
        assert_eq!(tr.check(h(1, 3), 0.2, 0.9), Err(Refusal::Stale));
        assert_eq!(tr.check(h(9, 0), 0.9, 0.9), Ok(()));
        let c = tr.counters;
        assert_eq!((c.accepted, c.reordered, c.stale, c.restarts), (3, 2, 1, 1));
    }
}
