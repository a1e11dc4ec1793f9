//! Liveness (issue trust2, item 4): dense symmetric encounters, everyone
//! gets home. Robots on a circle swap to the antipodes or to a random
//! permutation of the starts, or two rows swap sides head-on, every robot
//! running its own filter (decentralised, as in the fleet) on what it sees
//! of the others. Each reaches its goal within the stated bound
//! [`bound`] (linear in the circle's size and in N), and no two points come
//! closer than the radius less 1 mm.
//!
//! The filter is stepped by the caller, as `echelon.safety.Filter` is from
//! Python ([`run_direct`]), on ideal velocity bases and on Table I's
//! torque-driven robots (`python/tests/test_safety_swap.py` steps the
//! Python `Filter` itself). The same encounters under the formation laws,
//! from a scenario behind a slow reference, are `tests/safety_swap_sim.rs`
//! (open: not everyone gets home there yet).
//!
//! `cargo test -p echelon --release --test safety_swap -- --ignored
//! --nocapture compare` prints BENCHMARKS.md's table: arrival times of the
//! decentralised filters against a centralised barrier-certificate QP over
//! all robots ([`Centralised`]).
#![allow(clippy::unwrap_used)]

mod common;
use common::fixed_sample;

use clarabel::algebra::CscMatrix;
use clarabel::solver::{DefaultSettings, DefaultSolver, IPSolver, NonnegativeConeT, SolverStatus};
use echelon::State;
use echelon::base::{VelocityBase, VelocityCommand};
use echelon::model::{Input, RobotParams};
use echelon::safety::{Neighbour, Outcome, SafetyConfig, SafetyFilter, point};
use proptest::prelude::*;
use proptest::strategy::ValueTree;
use std::f64::consts::PI;

/// The robots' point ahead of the axle, m.
const L: f64 = 0.05;

/// A robot has arrived when its point is this close to its goal, m.
const ARRIVE: f64 = 0.02;

/// The filter's `γ`, 1/s.
const GAIN: f64 = 1.0;

/// How the robots are driven and how the filter sees them.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Drive {
    /// Ideal velocity bases (their speeds the commands they were sent,
    /// as Python's `Filter` takes `(n, 3)` poses).
    Velocity,
    /// Table I's agent 1 (eq. 3), a point-acceleration law.
    Torque,
}

/// One encounter: where every robot starts (its point, heading to its
/// goal) and its goal (for its point), the radius and the top speed of
/// the point the robots ask for.
#[derive(Debug, Clone)]
struct Encounter {
    starts: Vec<[f64; 2]>,
    goals: Vec<[f64; 2]>,
    radius: f64,
    speed: f64,
}

/// The smallest circle (radius, m) `n` robots fit on: circumference
/// `n · 2 · radius`, with 10 % to spare.
fn fits(n: usize, radius: f64) -> f64 {
    1.1 * n as f64 * 2.0 * radius / (2.0 * PI)
}

impl Encounter {
    /// `n` robots evenly on a circle of radius `circle`, robot `i` bound
    /// for the start of robot `to[i]` (the antipodal swap: `i + n/2`).
    fn circle(circle: f64, to: &[usize], radius: f64, speed: f64) -> Encounter {
        let n = to.len();
        let at = |i: usize| {
            let (s, c) = (2.0 * PI * i as f64 / n as f64).sin_cos();
            [circle * c, circle * s]
        };
        Encounter {
            starts: (0..n).map(at).collect(),
            goals: to.iter().map(|&j| at(j)).collect(),
            radius,
            speed,
        }
    }

    /// The antipodal swap of `n` robots on a circle of radius `circle`.
    fn antipodal(n: usize, circle: f64, radius: f64, speed: f64) -> Encounter {
        let to: Vec<usize> = (0..n).map(|i| (i + n / 2) % n).collect();
        let mut e = Encounter::circle(circle, &to, radius, speed);
        if n % 2 == 1 {
            e.goals = e.starts.iter().map(|p| [-p[0], -p[1]]).collect();
        }
        e
    }

    /// Two rows of `n/2` robots, `spacing` apart across, `gap` apart along
    /// x, facing each other; each row swaps to the other's places (a
    /// crowded crossing: every robot meets a wall of others head on).
    fn rows(n: usize, spacing: f64, gap: f64, radius: f64, speed: f64) -> Encounter {
        let m = n / 2;
        let y = |k: usize| (k as f64 - 0.5 * (m as f64 - 1.0)) * spacing;
        let mut starts = Vec::new();
        let mut goals = Vec::new();
        for k in 0..m {
            starts.push([-0.5 * gap, y(k)]);
            goals.push([0.5 * gap, y(k)]);
        }
        for k in 0..m {
            starts.push([0.5 * gap, y(k)]);
            goals.push([-0.5 * gap, y(k)]);
        }
        Encounter {
            starts,
            goals,
            radius,
            speed,
        }
    }

    fn n(&self) -> usize {
        self.starts.len()
    }

    /// The farthest any robot must go, m.
    fn farthest(&self) -> f64 {
        self.starts
            .iter()
            .zip(&self.goals)
            .map(|(s, g)| (g[0] - s[0]).hypot(g[1] - s[1]))
            .fold(0.0, f64::max)
    }

    /// Every robot at rest, its point at its start, facing its goal.
    fn states(&self) -> Vec<State> {
        self.starts
            .iter()
            .zip(&self.goals)
            .map(|(p, g)| {
                let heading = if (g[0] - p[0]).hypot(g[1] - p[1]) > 1e-9 {
                    (g[1] - p[1]).atan2(g[0] - p[0])
                } else {
                    (-p[1]).atan2(-p[0])
                };
                State::at_rest(p[0] - L * heading.cos(), p[1] - L * heading.sin(), heading)
            })
            .collect()
    }
}

/// The arrival-time bound, s, for `n` robots each going at most `farthest`
/// m at a point speed of at most `speed` m/s, kept `radius` m apart:
///
/// ```text
/// T ≤ farthest / speed + ln(speed / (k ARRIVE)) / k + n · 2 radius / speed + 10 s
/// ```
///
/// a free robot's time (the straight run at `speed`, then the exponential
/// approach at `k` = 1/s to within [`ARRIVE`]), plus a robot's diameter of
/// detour per robot it may have to wait for or go round (the jam at the
/// centre clears one robot at a time, each of the others passing round the
/// ones in the middle), plus 10 s for the deadlock monitor (1 s stuck before
/// a break, 1 s still before each further turn) and the turns themselves.
/// Linear in the circle's size (through `farthest`) and in N.
fn bound(n: usize, farthest: f64, radius: f64, speed: f64) -> f64 {
    farthest / speed + (speed / ARRIVE).ln() + n as f64 * 2.0 * radius / speed + 10.0
}

/// What a run showed.
#[derive(Debug, Clone)]
struct Seen {
    /// When each robot's point first came within [`ARRIVE`] of its goal, s
    /// (infinite: never).
    arrival: Vec<f64>,
    /// The smallest distance between two points, m.
    closest: f64,
    /// Deadlock breaks started, all robots.
    breaks: u64,
    /// Filter calls that found no command satisfying every row (the
    /// emergency action).
    braked: u64,
}

impl Seen {
    fn new(n: usize) -> Seen {
        Seen {
            arrival: vec![f64::INFINITY; n],
            closest: f64::INFINITY,
            breaks: 0,
            braked: 0,
        }
    }

    /// Records the points at `t`; whether every robot has arrived.
    fn record(&mut self, t: f64, points: &[[f64; 2]], goals: &[[f64; 2]]) -> bool {
        for (i, p) in points.iter().enumerate() {
            for q in &points[..i] {
                self.closest = self.closest.min((p[0] - q[0]).hypot(p[1] - q[1]));
            }
            let g = goals[i];
            if self.arrival[i].is_infinite() && (p[0] - g[0]).hypot(p[1] - g[1]) < ARRIVE {
                self.arrival[i] = t;
            }
        }
        self.arrival.iter().all(|a| a.is_finite())
    }

    fn last(&self) -> f64 {
        self.arrival.iter().copied().fold(0.0, f64::max)
    }
}

/// The point velocity a robot asks for: toward its goal at gain 1/s, at
/// most `speed` (Robotarium's single-integrator position controller).
fn desired(p: [f64; 2], goal: [f64; 2], speed: f64) -> [f64; 2] {
    let d = [goal[0] - p[0], goal[1] - p[1]];
    let k = (speed / d[0].hypot(d[1])).min(1.0);
    [k * d[0], k * d[1]]
}

/// The unicycle command that moves the point `L` ahead at `dp` (Robotarium's
/// `si_to_uni` for the point ahead: exact).
fn si_to_uni(s: &State, dp: [f64; 2]) -> VelocityCommand {
    let (sin, cos) = s.theta.sin_cos();
    VelocityCommand {
        v: cos * dp[0] + sin * dp[1],
        omega: (-sin * dp[0] + cos * dp[1]) / L,
    }
}

/// The torques that bring the point's velocity to `dp` at 5/s
/// (`p̈ = f + R(θ)(u1/m, L u2/J)`, eq. 3, solved for the inputs).
fn torque_law(robot: &RobotParams, s: &State, dp: [f64; 2]) -> Input {
    let (sin, cos) = s.theta.sin_cos();
    let (m, j) = (robot.mass(), robot.inertia());
    let (v, w) = (s.v, s.omega);
    let now = [v * cos - L * w * sin, v * sin + L * w * cos];
    let a = [5.0 * (dp[0] - now[0]), 5.0 * (dp[1] - now[1])];
    let along = -robot.linear_friction() * v / m - L * w * w;
    let across = v * w - L * robot.angular_friction() * w / j;
    let f = [along * cos - across * sin, along * sin + across * cos];
    let r = [a[0] - f[0], a[1] - f[1]];
    let x = [cos * r[0] + sin * r[1], -sin * r[0] + cos * r[1]];
    Input {
        u1: m * x[0],
        u2: j * x[1] / L,
    }
}

/// The encounter with one filter per robot stepped by the caller every
/// `dt` (as from Python), for at most `duration` s; stops when everyone
/// has arrived.
fn run_direct(e: &Encounter, drive: Drive, duration: f64) -> Seen {
    let n = e.n();
    let dt = if drive == Drive::Torque { 0.005 } else { 0.02 };
    let config = SafetyConfig::new(e.radius, GAIN, f64::INFINITY).unwrap();
    let mut filters: Vec<SafetyFilter> = (0..n)
        .map(|_| SafetyFilter::new(config).with_period(dt))
        .collect();
    let robot = RobotParams::AGENT1;
    let base = VelocityBase::IDEAL;
    let mut states = e.states();
    let mut next = states.clone();
    let mut neighbours = Vec::with_capacity(n);
    let mut points = vec![[0.0; 2]; n];
    let mut dv = vec![[0.0; 2]; n];
    let mut seen = Seen::new(n);
    let steps = (duration / dt).round() as usize;
    for k in 0..=steps {
        let t = k as f64 * dt;
        for (p, s) in points.iter_mut().zip(&states) {
            *p = point(s, L);
        }
        if seen.record(t, &points, &e.goals) || k == steps {
            break;
        }
        // Before any filter answers anew: each torque robot's acceleration
        // under what its filter answered at the last step, what it carries
        // out now.
        let torque = drive == Drive::Torque;
        for ((a, s), f) in dv.iter_mut().zip(&states).zip(&filters) {
            *a = f.last_acceleration(s, &robot);
        }
        for i in 0..n {
            neighbours.clear();
            for (j, s) in states.iter().enumerate() {
                if j != i {
                    let dv = torque.then_some(dv[j]);
                    neighbours.push(Neighbour::of_state(s, L, dv, true).sharing(torque));
                }
            }
            let me = &states[i];
            let dp = desired(points[i], e.goals[i], e.speed);
            next[i] = match drive {
                Drive::Velocity => {
                    let out =
                        filters[i].velocity(t, me, L, si_to_uni(me, dp), &base, &neighbours, &[]);
                    seen.braked += u64::from(out.outcome == Outcome::Braked);
                    base.rk4_step(&states[i], out.command, dt)
                }
                Drive::Torque => {
                    let nominal = torque_law(&robot, me, dp);
                    let out = filters[i].torque(t, me, L, &robot, nominal, &neighbours, &[]);
                    seen.braked += u64::from(out.outcome == Outcome::Braked);
                    robot.rk4_step(&states[i], out.command, dt)
                }
            };
        }
        std::mem::swap(&mut states, &mut next);
    }
    seen.breaks = filters.iter().map(|f| f.deadlock_breaks()).sum();
    seen
}

/// Checks a run against the bound and the radius (`inside`: how far inside
/// it two points may come, m).
fn check(e: &Encounter, seen: &Seen, what: &str, inside: f64) -> Result<(), TestCaseError> {
    let limit = bound(e.n(), e.farthest(), e.radius, e.speed);
    prop_assert!(
        seen.closest >= e.radius - inside,
        "{what}: points {} m apart, radius {}: {seen:?}\n{e:?}",
        seen.closest,
        e.radius
    );
    prop_assert!(
        seen.last() <= limit,
        "{what}: last arrival {} s, bound {limit} s: {seen:?}\n{e:?}",
        seen.last()
    );
    Ok(())
}

/// One case run on `drive` for its bound and 5 s more, checked against the
/// bound and the radius less `inside` m ([`check`]).
fn gets_home(
    drive: Drive,
    n: usize,
    layout: &Layout,
    radius: f64,
    speed: f64,
    inside: f64,
) -> Result<(), TestCaseError> {
    let e = encounter(n, layout, radius, speed);
    let limit = bound(n, e.farthest(), radius, speed);
    let seen = run_direct(&e, drive, limit + 5.0);
    check(&e, &seen, &format!("{n} robots, {drive:?}"), inside)
}

/// The layouts a case draws.
#[derive(Debug, Clone)]
enum Layout {
    /// The antipodal swap on a circle this much larger than the smallest
    /// the robots fit on.
    Antipodal(f64),
    /// A random permutation of the starts on such a circle.
    Permuted(f64, Vec<usize>),
    /// Two rows swapping: spacing across (m) and distance between rows (m).
    Rows(f64, f64),
}

fn encounter(n: usize, layout: &Layout, radius: f64, speed: f64) -> Encounter {
    match layout {
        Layout::Antipodal(k) => Encounter::antipodal(n, k * fits(n, radius), radius, speed),
        Layout::Permuted(k, to) => Encounter::circle(k * fits(n, radius), to, radius, speed),
        Layout::Rows(spacing, gap) => Encounter::rows(n, *spacing, *gap, radius, speed),
    }
}

/// Cases: N 4–16 (rows: the even number below), the layout, radius
/// 0.15–0.3 m, speed 0.1–0.3 m/s.
fn cases() -> impl Strategy<Value = (usize, Layout, f64, f64)> {
    (4usize..=16, 0.15..0.3f64, 0.1..0.3f64).prop_flat_map(|(n, radius, speed)| {
        let layout = prop_oneof![
            (1.0..2.0f64).prop_map(Layout::Antipodal),
            (1.0..2.0f64, Just((0..n).collect::<Vec<_>>()).prop_shuffle())
                .prop_map(|(k, to)| Layout::Permuted(k, to)),
            // Two rows of ⌊n/2⌋, 1.1–1.6 radii across, 1–3 m apart.
            (1.1..1.6f64, 1.0..3.0f64).prop_map(move |(s, g)| Layout::Rows(s * radius, g)),
        ];
        (Just(n), layout, Just(radius), Just(speed))
    })
}

proptest! {
    #![proptest_config(fixed_sample(common::env_or("SWAP_CASES", 48) as u32, common::env_or("SWAP_SEED", 7)))]

    /// Every robot of a random dense encounter (N 4–16; antipodal swap,
    /// permuted goals, two rows swapping; radius, speed and circle size
    /// random) reaches its goal within [`bound`], clearance kept: on ideal
    /// velocity bases, filters stepped by the caller.
    #[test]
    fn everyone_gets_home_on_velocity_bases((n, layout, radius, speed) in cases()) {
        gets_home(Drive::Velocity, n, &layout, radius, speed, 1e-3)?;
    }
}

proptest! {
    #![proptest_config(fixed_sample(common::env_or("SWAP_CASES", 24) as u32, common::env_or("SWAP_SEED", 8)))]

    /// The same on Table I's torque-driven robots (their point's
    /// acceleration the law's and the filter's variable): every robot home
    /// within [`bound`].
    //
    // Over 45 seeds × 40 cases of each drive by hand (`SWAP_SEED`,
    // `SWAP_CASES`): the clearance held to 1 mm in every case; 4 of the 3600
    // did not get home in time (OPEN: velocity bases on seeds 10 and 16,
    // 10–11 robots, some never home; seed 41 velocity, 2.9 s late; seed 43
    // torque, 3.1 s late; no tracking error is given here, so only the
    // motion tests act).
    #[test]
    fn everyone_gets_home_on_torque_robots((n, layout, radius, speed) in cases()) {
        gets_home(Drive::Torque, n, &layout, radius, speed, 1e-3)?;
    }
}

/// Counterexamples the proptests above found on seeds other than theirs
/// (12 seeds × 40 cases each, by hand, shrunk by proptest), every one now
/// home within the bound, clearance kept to 1 mm:
/// - velocity bases, two rows of 7 swapping (seed 10): robot 1 overshot
///   through the row, then crawled back beside parked robots at 1–2 mm/s
///   for 30 s, its break's turned desire nearly across their barriers (a
///   break now ends once the unturned nominal keeps nearly all its motion);
/// - torque robots, a 14-robot permutation (seed 2): two points 10.7 mm
///   inside the radius, a robot squeezed between two neighbours that both
///   closed on it (a torque robot now takes over what its neighbour fell
///   short of its half, `Neighbour::sharing`);
/// - torque robots, two rows of 3 (seed 10): last home 0.14 s after the
///   bound;
/// - torque robots, two rows of 6 (seed 8, with a first split): a robot
///   span on the spot behind parked robots for 30 s;
/// - torque robots, two rows of 4 (seed 8): a robot clear of everyone kept
///   its break's turned desire and circled away from its goal.
#[test]
fn counterexamples_found_on_other_seeds() {
    let cases = [
        (
            Drive::Velocity,
            14,
            Layout::Rows(0.301_265_908_675_088_1, 1.825_097_361_618_223_3),
            0.238_436_692_483_956_08,
            0.287_673_019_246_045_8,
        ),
        (
            Drive::Torque,
            14,
            Layout::Permuted(
                1.580_223_343_503_799,
                vec![4, 7, 2, 9, 11, 8, 0, 13, 12, 6, 3, 5, 1, 10],
            ),
            0.266_867_045_361_130_76,
            0.185_500_500_263_872_94,
        ),
        (
            Drive::Torque,
            7,
            Layout::Rows(0.215_810_843_645_254_66, 2.755_290_462_273_997_8),
            0.196_191_676_041_140_57,
            0.295_982_129_366_195_2,
        ),
        (
            Drive::Torque,
            12,
            Layout::Rows(0.197_850_268_693_336_13, 1.0),
            0.179_863_880_630_305_56,
            0.231_631_024_936_863_97,
        ),
        (
            Drive::Torque,
            8,
            Layout::Rows(0.256_626_781_085_513_23, 2.063_742_359_702_866),
            0.179_863_880_630_305_56,
            0.231_631_024_936_863_97,
        ),
    ];
    let failed: Vec<String> = cases
        .into_iter()
        .filter_map(|(drive, n, layout, radius, speed)| {
            gets_home(drive, n, &layout, radius, speed, 1e-3)
                .err()
                .map(|f| f.to_string().chars().take(200).collect())
        })
        .collect();
    assert!(failed.is_empty(), "{failed:#?}");
}

/// The user's report: unicycles at 0.15 m/s, radius 0.22 m between points
/// 5 cm ahead, the antipodal swap on a 0.8 m circle: 8 and 12 robots never
/// arrived in 60 s from Python, where a centralised QP gets them home in
/// 43 s and 40 s. Every robot home within the bound, and within 60 s.
#[test]
fn the_reported_swap_gets_everyone_home() {
    for n in [4, 8, 12] {
        let e = Encounter::antipodal(n, 0.8, 0.22, 0.15);
        for drive in [Drive::Velocity, Drive::Torque] {
            let seen = run_direct(&e, drive, 60.0);
            check(&e, &seen, &format!("{n} robots, {drive:?}"), 1e-3).unwrap();
            assert!(seen.last() < 60.0, "{seen:?}");
            assert!(seen.breaks > 0, "a symmetric swap needs a break: {seen:?}");
            // Deterministic: the same run again, the same arrivals to the bit.
            let again = run_direct(&e, drive, 60.0);
            assert_eq!(again.arrival, seen.arrival);
            assert_eq!(again.closest.to_bits(), seen.closest.to_bits());
        }
    }
}

proptest! {
    #![proptest_config(fixed_sample(64, 9))]

    /// The encounter rule: a robot whose nominal drives its point at a
    /// neighbour's faster than their barrier allows keeps right at once
    /// (from its second call, 10 ms on, not 1 s stuck) when the
    /// neighbour comes toward it, and does not when the neighbour moves
    /// along with it (ahead, the same way, slower than the nominal asks: a
    /// robot following or riding beside another is not in an encounter).
    /// Any heading, distance, speeds; ideal velocity base.
    #[test]
    fn a_robot_keeps_right_at_once_only_toward_an_oncoming_neighbour(
        heading in -PI..PI,
        radius in 0.15..0.4f64,
        gap in 0.01..0.1f64,
        speed in 0.1..0.5f64,
        other in 0.05..0.5f64,
        offset in -0.3..0.3f64,
    ) {
        let config = SafetyConfig::new(radius, GAIN, f64::INFINITY).unwrap();
        let (sin, cos) = heading.sin_cos();
        let mut me = State::at_rest(0.0, 0.0, heading);
        me.v = speed;
        let nominal = VelocityCommand { v: speed, omega: 0.0 };
        // The neighbour's point dead ahead (up to 0.3 rad off), just
        // beyond the radius.
        let dist = radius + gap;
        let bearing = heading + offset;
        let q = [L * cos + dist * bearing.cos(), L * sin + dist * bearing.sin()];
        let at = |theta: f64, v: f64| {
            let mut s = State::at_rest(q[0] - L * theta.cos(), q[1] - L * theta.sin(), theta);
            s.v = v;
            Neighbour::of_state(&s, L, None, true)
        };
        // Two calls 10 ms apart (a break started at one call turns the
        // desire from the next): whether the second breaks a deadlock.
        let run = |n: Neighbour| {
            let mut f = SafetyFilter::new(config);
            let base = VelocityBase::IDEAL;
            f.velocity(0.0, &me, L, nominal, &base, &[n], &[]);
            (f.velocity(0.01, &me, L, nominal, &base, &[n], &[]), f.deadlock_breaks())
        };
        // Oncoming: facing this robot, at `other`.
        let (oncoming, breaks) = run(at(heading + PI, other));
        prop_assert!(oncoming.active());
        prop_assert!(oncoming.deadlock && breaks == 1, "{oncoming:?}");
        // Along: the same heading, slower (this robot closes on it).
        let (along, breaks) = run(at(heading, other.min(0.5 * speed)));
        prop_assert!(!along.deadlock && breaks == 0, "{along:?}");
    }
}

/// `SWAP_SURVEY=N cargo test -p echelon --test safety_swap -- --ignored
/// survey --nocapture`: N cases of each drive, the last arrival against the bound.
#[test]
#[ignore = "a survey for development"]
fn survey() {
    let mut runner = proptest::test_runner::TestRunner::new(fixed_sample(1, 99));
    let k = common::env_or("SWAP_SURVEY", 20);
    for _ in 0..k {
        let (n, layout, radius, speed) = cases().new_tree(&mut runner).unwrap().current();
        let e = encounter(n, &layout, radius, speed);
        let limit = bound(n, e.farthest(), radius, speed);
        let mut line = format!(
            "n {n:2} {:>9} r {radius:.2} s {speed:.2} bound {limit:5.1}:",
            format!("{layout:?}").chars().take(9).collect::<String>()
        );
        for drive in [Drive::Velocity, Drive::Torque] {
            let seen = run_direct(&e, drive, 2.0 * limit);
            line += &format!(
                " {drive:?} {:.2} ({:.3}, braked {})",
                seen.last() / limit,
                seen.closest - radius,
                seen.braked
            );
        }
        println!("{line}");
    }
}

/// A centralised barrier-certificate QP over all robots, the comparison of
/// BENCHMARKS.md (Robotarium's `create_single_integrator_barrier_certificate`
/// with the points `L` ahead mapped to unicycles by `si_to_uni`): every
/// point's velocity `ṗ_i` at once,
///
/// ```text
/// min Σ ½‖ṗ_i − ṗ_i⁰‖²   s.t.   2 (p_i − p_j)ᵀ (ṗ_i − ṗ_j) ≥ −γ h_ij   (every pair i < j)
/// ```
///
/// (the whole pair constraint, no split: one solver sees both robots), by
/// clarabel; the same `γ`, radius, nominal and unicycles as [`run_direct`].
/// A study, not a filter: it allocates and solves `2N` variables each step.
fn run_centralised(e: &Encounter, duration: f64) -> Seen {
    let n = e.n();
    let dt = 0.02;
    let base = VelocityBase::IDEAL;
    let mut states = e.states();
    let mut seen = Seen::new(n);
    let mut points = vec![[0.0; 2]; n];
    let steps = (duration / dt).round() as usize;
    for k in 0..=steps {
        let t = k as f64 * dt;
        for (p, s) in points.iter_mut().zip(&states) {
            *p = point(s, L);
        }
        if seen.record(t, &points, &e.goals) || k == steps {
            break;
        }
        let want: Vec<f64> = (0..n)
            .flat_map(|i| desired(points[i], e.goals[i], e.speed))
            .collect();
        let dp = centralised_qp(&points, &want, e.radius).unwrap_or_else(|| vec![0.0; 2 * n]);
        for (i, s) in states.iter_mut().enumerate() {
            *s = base.rk4_step(s, si_to_uni(s, [dp[2 * i], dp[2 * i + 1]]), dt);
        }
    }
    seen
}

/// The centralised QP's answer (`ṗ` of every point, stacked), `None` if
/// clarabel reports no solution.
fn centralised_qp(points: &[[f64; 2]], want: &[f64], radius: f64) -> Option<Vec<f64>> {
    let n = points.len();
    let pairs: Vec<(usize, usize)> = (0..n)
        .flat_map(|i| (i + 1..n).map(move |j| (i, j)))
        .collect();
    // clarabel's form A z ≤ b: −2dᵀ(ṗ_i − ṗ_j) ≤ γ h, built column by column.
    let mut colptr = vec![0];
    let mut rowval = Vec::new();
    let mut nz = Vec::new();
    for c in 0..2 * n {
        let (robot, axis) = (c / 2, c % 2);
        for (r, &(i, j)) in pairs.iter().enumerate() {
            let d = points[i][axis] - points[j][axis];
            if robot == i {
                rowval.push(r);
                nz.push(-2.0 * d);
            } else if robot == j {
                rowval.push(r);
                nz.push(2.0 * d);
            }
        }
        colptr.push(nz.len());
    }
    let a = CscMatrix::new(pairs.len(), 2 * n, colptr, rowval, nz);
    let b: Vec<f64> = pairs
        .iter()
        .map(|&(i, j)| {
            let d = [points[i][0] - points[j][0], points[i][1] - points[j][1]];
            GAIN * (d[0] * d[0] + d[1] * d[1] - radius * radius)
        })
        .collect();
    let p = CscMatrix::identity(2 * n);
    let q: Vec<f64> = want.iter().map(|w| -w).collect();
    let settings = DefaultSettings {
        verbose: false,
        ..DefaultSettings::default()
    };
    let cones = [NonnegativeConeT(b.len())];
    let mut solver = DefaultSolver::new(&p, &q, &a, &b, &cones, settings).ok()?;
    solver.solve();
    matches!(
        solver.solution.status,
        SolverStatus::Solved | SolverStatus::AlmostSolved
    )
    .then(|| solver.solution.x.clone())
}

/// BENCHMARKS.md's table: the user's report (radius 0.22 m, 0.15 m/s,
/// points 5 cm ahead, the antipodal swap) for N = 4, 8, 12, 16 on circles
/// of 0.8 m and 1.6 m: the last arrival (s) with the decentralised filters
/// (ideal velocity bases; Table I torque robots) and with the centralised
/// QP, 120 s at most (`—`: someone had not arrived).
#[test]
#[ignore = "a study: run in release with --nocapture"]
fn compare() {
    let time = |s: &Seen| {
        if s.last().is_finite() {
            format!("{:.1}", s.last())
        } else {
            format!(
                "— ({} of {})",
                s.arrival.iter().filter(|a| a.is_finite()).count(),
                s.arrival.len()
            )
        }
    };
    println!(
        "| N | circle (m) | bound (s) | decentralised, velocity | decentralised, torque | centralised QP | closest, m (velocity / torque / centralised) |"
    );
    println!("|---|---|---|---|---|---|---|");
    for circle in [0.8, 1.6] {
        for n in [4, 8, 12, 16] {
            let e = Encounter::antipodal(n, circle, 0.22, 0.15);
            let limit = bound(n, e.farthest(), e.radius, e.speed);
            let d = run_direct(&e, Drive::Velocity, 120.0);
            let tq = run_direct(&e, Drive::Torque, 120.0);
            let c = run_centralised(&e, 120.0);
            println!(
                "| {n} | {circle} | {limit:.1} | {} | {} | {} | {:.4} / {:.4} / {:.4} |",
                time(&d),
                time(&tq),
                time(&c),
                d.closest,
                tq.closest,
                c.closest
            );
        }
    }
}
