//! Fault injection on what a robot receives (`--loss`, `--delay`, `--outage`),
//! seeded and reproducible: the same seed and the same arrivals give the same
//! drop pattern; faults of the process itself (`--freeze-odometry`, a
//! simulated robot's odometry frozen; `--die-at`, the process killed with
//! SIGKILL at a fleet time); and what a simulated robot did after a fault
//! ([`Aftermath`]: how far it travelled, when it was commanded zero and
//! came to rest), which the fault matrix (`fleet faults`) measures.

use echelon::rng::SplitMix64;

/// What the injector does (also a robot file's `[rehearsal]`,
/// [`crate::robot::RobotFile`]: every field optional).
#[derive(Debug, Clone, Copy, PartialEq, Default, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct FaultSpec {
    /// Probability in `[0, 1]` that a message is dropped.
    #[serde(skip_serializing_if = "is_zero")]
    pub loss: f64,
    /// Extra delay added to every message, fleet s.
    #[serde(skip_serializing_if = "is_zero")]
    pub delay: f64,
    /// `(start, length)`, fleet s: everything arriving in `[start, start + length)` is dropped.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub outage: Option<(f64, f64)>,
    /// Seed of the drop pattern.
    #[serde(skip_serializing_if = "is_zero_seed")]
    pub seed: u64,
    /// `(start, length)`, fleet s: a simulated robot's odometry stops
    /// updating (its state stays where it was at `start`, its age grows)
    /// while the robot itself moves on.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub freeze_odometry: Option<(f64, f64)>,
    /// A simulated robot measures what it does from this fleet time on
    /// ([`Aftermath`]).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub fault_at: Option<f64>,
    /// For how long after `fault_at` it measures, s (`None`: to the end).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub fault_window: Option<f64>,
    /// `(at, step)`: the process's wall clock steps by `step` s at fleet
    /// time `at` (an NTP step; fleet time is monotonic).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub wall_clock_jump: Option<(f64, f64)>,
    /// `(start, length)`, fleet s: the robot partitioned from the fleet
    /// ([`FaultSpec::partitioned_at`]): nothing in, nothing out.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub partition: Option<(f64, f64)>,
}

fn is_zero(v: &f64) -> bool {
    *v == 0.0
}

fn is_zero_seed(v: &u64) -> bool {
    *v == 0
}

/// Faults `fleet up` injects into its own processes at fleet times: the
/// fault matrix's rows (`fleet faults`, [`crate::matrix`]).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Chaos {
    /// Every simulated robot measures its aftermath from this fleet time
    /// (`--fault-at`), for `window` s (`None`: to the end).
    pub fault_at: Option<f64>,
    /// How long the aftermath is measured.
    pub window: Option<f64>,
    /// Processes that kill themselves with SIGKILL at a fleet time
    /// (`--die-at`): the leader, a robot, the operator's heartbeat. Their
    /// deaths are expected: `fleet up` reports them and runs on.
    pub kills: Vec<(crate::role::Member, f64)>,
    /// Robot `k`'s odometry frozen in `(start, length)`.
    pub freeze_odometry: Vec<(u32, (f64, f64))>,
    /// Robot `k`'s leader stream cut in `(start, length)`.
    pub outages: Vec<(u32, (f64, f64))>,
    /// Robot `k` partitioned in `(start, length)`
    /// ([`FaultSpec::partitioned_at`]): nothing in or out but the fleet's
    /// stop and heartbeat keys.
    pub partitions: Vec<(u32, (f64, f64))>,
    /// `(start, length)`: garbage, duplicates and replays on every key of
    /// the fleet (`fleet garbage`, [`crate::garbage`]).
    pub garbage: Option<(f64, f64)>,
    /// `(at, down)`: site 1's router killed with SIGKILL at fleet time
    /// `at`, started again on its port `down` fleet s later.
    pub router_restart: Option<(f64, f64)>,
    /// Robot `k`'s wall clock stepped by `step` s at fleet time `at`.
    pub wall_clock_jumps: Vec<(u32, (f64, f64))>,
    /// At about this fleet time (real time since the leader started, over
    /// the time scale, plus a second for its start-up) a second leader and
    /// a second robot 2 of the same fleet join the router: what a second
    /// `fleet up` of the same fleet name reaching this router would start.
    /// Each must be refused.
    pub intruders: Option<f64>,
}

impl Chaos {
    /// When `member` is to kill itself, if it is.
    pub fn death_of(&self, member: crate::role::Member) -> Option<f64> {
        self.kills
            .iter()
            .find(|(m, _)| *m == member)
            .map(|&(_, t)| t)
    }
}

impl FaultSpec {
    /// Whether nothing of the leader stream arrives at fleet time `t` (an
    /// `outage`, or a `partition`).
    pub fn leader_cut_at(&self, t: f64) -> bool {
        let within = |w: Option<(f64, f64)>| w.is_some_and(|(s, l)| t >= s && t < s + l);
        within(self.outage) || within(self.partition)
    }

    /// Whether the robot is partitioned from the fleet at fleet time `t`:
    /// nothing of its leader stream or its neighbours arrives, and its
    /// state and counters do not leave (its followers lose it as they
    /// would a robot behind a dead link); only the fleet's stop, resume and
    /// heartbeat keys still pass.
    pub fn partitioned_at(&self, t: f64) -> bool {
        self.partition
            .is_some_and(|(start, len)| t >= start && t < start + len)
    }

    /// Whether it injects anything on what the robot receives.
    pub fn is_active(&self) -> bool {
        self.loss > 0.0 || self.delay > 0.0 || self.outage.is_some() || self.partition.is_some()
    }

    /// Whether the odometry is frozen at fleet time `t`.
    pub fn odometry_frozen(&self, t: f64) -> bool {
        self.freeze_odometry
            .is_some_and(|(start, len)| t >= start && t < start + len)
    }
}

/// Kills this process with SIGKILL if fleet time `t` reached `die_at`
/// (`--die-at`), saying so on stderr first: the fault matrix's `kill -9`,
/// at a fleet time rather than a wall time.
pub fn die_if_due(die_at: Option<f64>, t: f64, role: &str) {
    if die_at.is_some_and(|at| t >= at) {
        eprintln!("{role}: --die-at reached at t = {t:.3} s: SIGKILL");
        let _ =
            rustix::process::kill_process(rustix::process::getpid(), rustix::process::Signal::KILL);
        // SIGKILL cannot be caught; should it fail, abort as abruptly.
        std::process::abort();
    }
}

/// What a simulated robot did from the fault on, measured on its true
/// state at every step of its clock.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Aftermath {
    at: f64,
    until: f64,
    last: Option<(f64, [f64; 2])>,
    speed_at_fault: Option<f64>,
    travel: f64,
    displacement_from: Option<[f64; 2]>,
    farthest: f64,
    zero_at: Option<f64>,
    moving_until: f64,
    slowest_tick: f64,
}

/// Below this speed a robot is at rest, m/s (a law settling onto a point
/// at rest creeps slower than this within a few seconds).
pub const AT_REST: f64 = 5e-3;

/// [`Aftermath`] as reported (JSON in robot and base reports).
#[derive(
    Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize, schemars::JsonSchema,
)]
#[serde(deny_unknown_fields)]
pub struct AftermathReport {
    /// The fault's fleet time, s.
    pub fault_at: f64,
    /// `|v|` at the fault, m/s (`null`: the robot was not running yet).
    pub speed_at_fault: Option<f64>,
    /// Path length from the fault to the end, m.
    pub travel: f64,
    /// The largest distance from where it was at the fault, m.
    pub farthest: f64,
    /// Seconds from the fault to the first zero command (`null`: never).
    pub time_to_zero: Option<f64>,
    /// Seconds from the fault until it last moved faster than [`AT_REST`]
    /// (0: at rest from the fault on).
    pub moving_for: f64,
    /// Whether it moved at the end of the measurement.
    pub moving_at_end: bool,
    /// The longest interval between two of its observations (its control
    /// ticks) from the fault to its first zero command, s: the tick that
    /// notices the fault comes at most this long after it could have (a
    /// loaded machine starts a tick late; the fault matrix's bound takes
    /// it in place of one control period when it is longer).
    #[serde(default)]
    pub slowest_tick: f64,
}

impl Aftermath {
    /// Measures from fleet time `at` for `window` s (`None`: for ever).
    pub fn new(at: f64, window: Option<f64>) -> Self {
        Aftermath {
            at,
            until: at + window.unwrap_or(f64::INFINITY),
            last: None,
            speed_at_fault: None,
            travel: 0.0,
            displacement_from: None,
            farthest: 0.0,
            zero_at: None,
            moving_until: at,
            slowest_tick: 0.0,
        }
    }

    /// The robot at fleet time `t` at `position` moving at `speed` (`|v|`),
    /// commanded zero (`zero`) or not.
    pub fn observe(&mut self, t: f64, position: [f64; 2], speed: f64, zero: bool) {
        if t < self.at || t > self.until {
            return;
        }
        let from = *self.displacement_from.get_or_insert(position);
        self.speed_at_fault.get_or_insert(speed);
        if let Some((tl, p)) = self.last {
            self.travel += (position[0] - p[0]).hypot(position[1] - p[1]);
            if self.zero_at.is_none() {
                // Detecting: the tick that notices comes at most this late.
                self.slowest_tick = self.slowest_tick.max(t - tl);
            }
        }
        self.farthest = self
            .farthest
            .max((position[0] - from[0]).hypot(position[1] - from[1]));
        if zero && self.zero_at.is_none() {
            self.zero_at = Some(t);
        }
        if speed > AT_REST {
            self.moving_until = t;
        }
        self.last = Some((t, position));
    }

    /// What it measured.
    pub fn report(&self) -> AftermathReport {
        AftermathReport {
            fault_at: self.at,
            speed_at_fault: self.speed_at_fault,
            travel: self.travel,
            farthest: self.farthest,
            time_to_zero: self.zero_at.map(|t| t - self.at),
            moving_for: self.moving_until - self.at,
            moving_at_end: self
                .last
                .is_some_and(|(t, _)| t <= self.moving_until && t > self.at),
            slowest_tick: self.slowest_tick,
        }
    }
}

/// What happens to one arriving message.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Verdict {
    /// Dropped by `--loss`.
    Lost,
    /// Dropped by `--outage`.
    Outage,
    /// Delivered at this fleet time.
    DeliverAt(f64),
}

/// Applies a [`FaultSpec`] to arrivals.
#[derive(Debug, Clone)]
pub struct FaultInjector {
    spec: FaultSpec,
    rng: SplitMix64,
}

impl FaultInjector {
    /// An injector; `stream` (e.g. the agent number) decorrelates robots that
    /// share a seed.
    pub fn new(spec: FaultSpec, stream: u64) -> Self {
        FaultInjector {
            spec,
            rng: SplitMix64::new(spec.seed ^ stream.wrapping_mul(0xD1B5_4A32_D192_ED03)),
        }
    }

    /// The verdict for a message arriving at fleet time `t`. One random draw
    /// per arrival, whatever the verdict, so the pattern depends only on the
    /// seed and the arrival count.
    pub fn admit(&mut self, t: f64) -> Verdict {
        let draw = self.rng.next_f64();
        if self.spec.leader_cut_at(t) {
            return Verdict::Outage;
        }
        if draw < self.spec.loss {
            return Verdict::Lost;
        }
        Verdict::DeliverAt(t + self.spec.delay)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pattern(seed: u64, loss: f64) -> Vec<bool> {
        let mut f = FaultInjector::new(
            FaultSpec {
                loss,
                seed,
                ..FaultSpec::default()
            },
            1,
        );
        (0..10_000)
            .map(|i| matches!(f.admit(i as f64 * 0.01), Verdict::Lost))
            .collect()
    }

    #[test]
    fn same_seed_same_pattern_and_the_rate_is_right() {
        let a = pattern(42, 0.2);
        assert_eq!(a, pattern(42, 0.2));
        assert_ne!(a, pattern(43, 0.2));
        let rate = a.iter().filter(|&&l| l).count() as f64 / a.len() as f64;
        // Binomial(10000, 0.2): σ = 0.004; 5σ.
        assert!((rate - 0.2).abs() < 0.02, "{rate}");
        assert!(pattern(1, 0.0).iter().all(|l| !l));
    }

    #[test]
    fn outage_and_delay() {
        let mut f = FaultInjector::new(
            FaultSpec {
                delay: 0.05,
                outage: Some((1.0, 3.0)),
                ..FaultSpec::default()
            },
            2,
        );
        assert_eq!(f.admit(0.5), Verdict::DeliverAt(0.55));
        assert_eq!(f.admit(1.0), Verdict::Outage);
        assert_eq!(f.admit(3.99), Verdict::Outage);
        assert_eq!(f.admit(4.0), Verdict::DeliverAt(4.05));
    }

    /// A robot braking from `v0` at `a` from the fault on: the path is
    /// `v0²/2a`, the time to rest `v0/a`, measured on a fine clock.
    #[test]
    fn aftermath_of_a_constant_deceleration() {
        for (v0, a, at) in [(0.3, 0.9, 2.0), (0.15, 0.5, 0.0), (1.0, 2.0, 7.5)] {
            let mut m = Aftermath::new(at, None);
            let dt = 1e-3;
            let mut t = at - 1.0;
            while t < at + 2.0 * v0 / a + 1.0 {
                let s = (t - at).max(0.0);
                let v = (v0 - a * s).max(0.0);
                let x = if t < at {
                    v0 * (t - at)
                } else {
                    v0 * s.min(v0 / a) - 0.5 * a * s.min(v0 / a).powi(2)
                };
                m.observe(t, [x, 0.0], v, t >= at);
                t += dt;
            }
            let r = m.report();
            let want = v0 * v0 / (2.0 * a);
            assert!(
                (r.travel - want).abs() < 1e-3 * want + v0 * dt,
                "{r:?} {want}"
            );
            assert!((r.farthest - want).abs() < 1e-3 * want + v0 * dt, "{r:?}");
            assert!(
                (r.moving_for - v0 / a).abs() < 2.0 * dt + AT_REST / a,
                "{r:?}"
            );
            assert!(r.time_to_zero.is_some_and(|z| z < dt), "{r:?}");
            assert!(!r.moving_at_end);
            assert!(r.speed_at_fault.is_some_and(|s| (s - v0).abs() < a * dt));
        }
    }

    proptest::proptest! {
        /// `slowest_tick` is the longest gap between two observations from
        /// the fault to the first zero command, whatever the gaps before
        /// the fault and after it (ticks at random intervals, the zero at a
        /// random tick).
        #[test]
        fn the_slowest_tick_is_the_longest_gap_until_the_first_zero(
            gaps in proptest::collection::vec(1e-3..0.2f64, 2..60),
            at in 0.0..1.0f64,
            zero in 0usize..60,
        ) {
            let mut m = Aftermath::new(at, None);
            let mut t = 0.0;
            let mut seen: Vec<f64> = Vec::new();
            for (k, g) in gaps.iter().enumerate() {
                t += g;
                m.observe(t, [t, 0.0], 0.1, k >= zero);
                if t >= at && (k <= zero || seen.is_empty()) {
                    seen.push(t);
                }
            }
            let want = seen.windows(2).map(|w| w[1] - w[0]).fold(0.0, f64::max);
            proptest::prop_assert_eq!(m.report().slowest_tick, want);
        }
    }

    #[test]
    fn uniform_draws_are_in_range() {
        let mut r = SplitMix64::new(7);
        for _ in 0..1000 {
            let x = r.next_f64();
            assert!((0.0..1.0).contains(&x));
        }
    }
}
