//! A robot whose slot lies across a neighbour that holds its own slot: the
//! filter must not leave it riding beside that neighbour for ever.
//!
//! The fleet found the case: `fleet up crossing --loss 0.3 --delay 30
//! --outage 10:0.5` ended with robot 5 riding along robot 2's barrier,
//! robot 2 between it and its slot, 1.34 m off, reported deadlocked. Both
//! move with the formation. Robot 5's nominal is the formation's motion plus
//! a push toward its slot, straight through robot 2 (`e` along the pair's
//! `d`); the barrier row toward robot 2 takes away exactly that push and
//! leaves the formation's motion, tangent to the barrier and equal to robot
//! 2's: the pair's distance settles at the radius and nothing changes any
//! more (an equilibrium of the filtered loop, not of the law). Most of the
//! nominal survives, so the motion test never calls the robot stuck; and a
//! robot breaking a deadlock there never stands still (it moves at the
//! formation's speed), so it never tried another turn. The monitor now also
//! asks for progress: while the filter acts, ‖e‖ must fall by 10 % within
//! 5 s (`echelon::safety::PROGRESS_WINDOW`), or the point move by 10 % of
//! ‖e‖ relative to what is nearest it, else it starts breaking or turns
//! further (`safety/deadlock.rs`).
//!
//! Three robots behind a line at any heading and speed: `j` holds a slot on
//! the line; `k` a slot `sep` to its left and 0.5 m ahead; the robot `i`
//! follows `k`, 0.5 m behind it, so its slot is `sep` left of `j`'s. `i`
//! starts on `j`'s right, abeam (± 0.3 radius along), just outside the
//! radius, all three at the formation's speed. Randomized over the drive
//! (Table I torque robots with and without wheel torque limits, ideal and
//! lagged velocity bases), radius, gain, gains of the law, speed, heading,
//! `sep`, the start along and across, and whether `j` filters.
#![allow(clippy::unwrap_used)]

mod common;

use common::{Watched, env_or};
use proptest::prelude::*;
use proptest::test_runner::RngSeed;

/// The robots' drive.
#[derive(Debug, Clone, Copy)]
enum Kind {
    /// A Table I preset, with an optional wheel torque limit, N m.
    Torque(&'static str, Option<f64>),
    /// A velocity base preset under the kinematic law (`ideal` with
    /// `v_max = 0.5 m/s` and this `omega_max`, rad/s).
    Velocity(&'static str, f64),
}

impl Kind {
    /// The base's top speed, m/s (the reference must stay below it).
    fn v_max(&self) -> f64 {
        match self {
            Kind::Velocity("turtlebot3-burger", _) => 0.22,
            Kind::Velocity("turtlebot4", _) => 0.306,
            _ => 0.5,
        }
    }
}

#[derive(Debug, Clone, Copy)]
struct Case {
    kind: Kind,
    /// The safety radius, m.
    radius: f64,
    /// The filter's `γ`, 1/s.
    gain: f64,
    /// The law's `ke` (and `kz` for torques).
    ke: f64,
    kz: f64,
    /// The reference's speed (m/s) and heading (rad).
    speed: f64,
    heading: f64,
    /// How far left of `j`'s slot `i`'s slot is, m.
    sep: f64,
    /// `i`'s start from abeam of `j`, along the line (m; + ahead), and its
    /// distance beyond the radius, m.
    along: f64,
    gap: f64,
    /// Whether `j` filters (else `i` takes the whole pair).
    cooperative: bool,
}

/// The robots' point is this far ahead of their axle, m.
const L: f64 = 0.05;

/// The run's length, s.
const DURATION: f64 = 90.0;

impl Case {
    fn toml(&self) -> String {
        let mut s = String::from("name = \"livelock\"\n");
        match self.kind {
            Kind::Torque(preset, limit) => {
                s += &format!("[sim]\nduration = {DURATION}\ndt = 0.005\n[log]\ndt = 0.1\n");
                s += &format!(
                    "[control]\nlaw = \"complete\"\nke = {}\nkz = {}\nl = {L}\nlycomp = \"none\"\n",
                    self.ke, self.kz
                );
                s += &format!("[robots.r]\npreset = \"{preset}\"\n");
                if let Some(t) = limit {
                    s += &format!("torque_limit = {t}\n");
                }
            }
            Kind::Velocity(preset, omega_max) => {
                s += &format!("[sim]\nduration = {DURATION}\ndt = 0.01\n[log]\ndt = 0.1\n");
                s += &format!(
                    "[control]\nlaw = \"kinematic\"\nke = {}\nl = {L}\nlycomp = \"none\"\n",
                    self.ke
                );
                s += &format!("[robots.r]\ndrive = \"velocity\"\npreset = \"{preset}\"\n");
                if preset == "ideal" {
                    s += &format!("v_max = 0.5\nomega_max = {omega_max}\n");
                }
            }
        }
        let (sin, cos) = self.heading.sin_cos();
        s += &format!(
            "[reference.line]\nspeed = {}\nstart = {{ x = 0.0, y = 0.0, theta = {} }}\n",
            self.speed, self.heading
        );
        s += &format!(
            "[safety]\nradius = {}\ngain = {}\nrange = 1.5\n",
            self.radius, self.gain
        );
        // An agent whose point starts at `p` (the reference's frame: x
        // ahead, y left), heading along the line at the reference's speed.
        let agent = |p: [f64; 2], leader: &str, offset: [f64; 2], extra: &str| {
            let w = [p[0] * cos - p[1] * sin, p[0] * sin + p[1] * cos];
            format!(
                "[[agents]]\nrobot = \"r\"\nstart = {{ x = {}, y = {}, theta = {}, v = {} }}\nleader = {leader}\noffset = {{ x = {}, y = {} }}\n{extra}",
                w[0] - L * cos,
                w[1] - L * sin,
                self.heading,
                self.speed,
                offset[0],
                offset[1]
            )
        };
        let j_extra = if self.cooperative {
            ""
        } else {
            "safety = { enabled = false }\n"
        };
        // j: on the line, 1 m behind the reference.
        s += &agent([-1.0, 0.0], "\"reference\"", [1.0, 0.0], j_extra);
        // k: `sep` left of the line, 0.5 m behind the reference.
        s += &agent([-0.5, self.sep], "\"reference\"", [0.5, -self.sep], "");
        // i: follows k 0.5 m behind (its slot `sep` left of j's); starts on
        // j's right, just outside the radius.
        let r = self.radius + self.gap;
        let across = (r * r - self.along * self.along).sqrt();
        s += &agent([-1.0 + self.along, -across], "2", [0.5, 0.0], "");
        s
    }
}

fn run(case: &Case) -> Watched {
    common::watch(&case.toml(), "livelock.toml", 0.01)
}

/// Random cases; `j` filters unless `either` (then it may not).
fn cases(either: bool) -> impl Strategy<Value = Case> {
    let kind = prop_oneof![
        Just(Kind::Torque("agent1", None)),
        Just(Kind::Torque("agent2", None)),
        (8.0..40.0f64).prop_map(|t| Kind::Torque("agent1", Some(t))),
        (1.5..4.0f64).prop_map(|w| Kind::Velocity("ideal", w)),
        Just(Kind::Velocity("turtlebot3-burger", 0.0)),
        Just(Kind::Velocity("turtlebot4", 0.0)),
        Just(Kind::Velocity("jackal", 0.0)),
    ];
    (
        kind,
        (0.15..0.35f64, 0.5..3.0f64, 0.5..2.0f64, 5.0..15.0f64),
        (0.3..0.8f64, -3.1..3.1f64, 0.05..0.6f64),
        (
            -0.3..0.3f64,
            0.001..0.05f64,
            any::<bool>().prop_map(move |c| c || !either),
        ),
    )
        .prop_map(
            |(kind, (radius, gain, ke, kz), (speed, heading, sep), (along, gap, coop))| {
                // The reference at 30–80 % of the base's top speed, at most
                // 0.3 m/s; the slot at least 5 cm beyond j's barrier.
                let speed = (speed * kind.v_max()).min(0.3);
                let ke = match kind {
                    Kind::Torque(..) => 1.0 + ke,
                    Kind::Velocity(..) => ke,
                };
                Case {
                    kind,
                    radius,
                    gain,
                    ke,
                    kz,
                    speed,
                    heading,
                    sep: radius + sep,
                    along: along * radius,
                    gap,
                    cooperative: coop,
                }
            },
        )
}

fn check(case: &Case) -> Result<(), TestCaseError> {
    let seen = run(case);
    let src = case.toml();
    prop_assert!(seen.bad.is_none(), "{seen:?}\n{src}");
    prop_assert!(seen.closest >= case.radius - 1e-3, "{seen:?}\n{src}");
    for (e, d) in seen.finals.iter().zip(&seen.deadlocked) {
        prop_assert!(
            *e < 0.01 && !d,
            "held beside a neighbour between it and its slot: {seen:?}\n{src}"
        );
    }
    Ok(())
}

proptest! {
    // A fixed seed, so CI runs the same sample (LIVELOCK_CASES=N for more,
    // LIVELOCK_SEED=K for another).
    #![proptest_config(ProptestConfig {
        cases: env_or("LIVELOCK_CASES", 24) as u32,
        rng_seed: RngSeed::Fixed(env_or("LIVELOCK_SEED", 11)),
        failure_persistence: None,
        ..ProptestConfig::default()
    })]

    /// A robot abeam of a filtering neighbour (as every fleet robot with
    /// `[safety]` is) that sits between it and its slot gets round it: every
    /// robot ends within 1 cm of its slot, none held, the points never more
    /// than 1 mm inside the radius. (Before the progress test 42 of 50 such
    /// cases ended with a robot riding beside the other. Until the
    /// encounter rule of issue trust2, item 4, this fixed sample found a
    /// torque `agent1` case, its slot 5 cm beyond the neighbour's barrier,
    /// γ = 0.5, in a limit cycle of about 30 s: its breaks took it part way
    /// round, its unbiased nominal brought it back; the test was ignored.
    /// With that rule, which keeps a robot right at once while it closes on
    /// an oncoming neighbour (`echelon::safety::ENCOUNTER_SHARE`), the whole
    /// sample reaches its slots.)
    #[test]
    fn a_robot_beside_a_neighbour_in_its_way_gets_round(case in cases(false)) {
        check(&case)?;
    }
}

/// The fleet's crossing in the simulator's terms: ideal bases with
/// `crossing`'s limits (0.5 m/s, 3 rad/s), radius 0.3 m, `γ = 1/s`,
/// `ke = 1`, 0.15 m/s along +x, the slot 0.5 m across a cooperative
/// neighbour, the robot starting abeam on its far side. Before the progress
/// test it rode there to the end, 0.79 m off, never stuck (no break).
#[test]
fn the_crossing_ride_along_is_broken() {
    let case = Case {
        kind: Kind::Velocity("ideal", 3.0),
        radius: 0.3,
        gain: 1.0,
        ke: 1.0,
        kz: 10.0,
        speed: 0.15,
        heading: 0.0,
        sep: 0.5,
        along: 0.0,
        gap: 0.001,
        cooperative: true,
    };
    let seen = run(&case);
    assert!(seen.bad.is_none(), "{seen:?}");
    assert!(seen.closest >= case.radius - 1e-3, "{seen:?}");
    assert!(seen.finals.iter().all(|e| *e < 0.01), "{seen:?}");
    assert!(seen.deadlocked.iter().all(|d| !d), "{seen:?}");
    assert!(seen.breaks >= 1, "it had to break a deadlock: {seen:?}");
}

/// `LIVELOCK_SURVEY=N cargo test --test safety_livelock -- --ignored
/// survey`: N cases, neighbours filtering or not, every failure listed (the proptest stops at the first);
/// with `LIVELOCK_DUMP=DIR` their scenario files are written there instead.
#[test]
#[ignore = "a survey for development: many cases"]
fn survey() {
    let dump = std::env::var("LIVELOCK_DUMP").ok();
    common::survey(cases(true), env_or("LIVELOCK_SURVEY", 200), |k, case| {
        match &dump {
            // The cases as scenario files, for `echelon run` of any build.
            Some(dir) => {
                std::fs::write(format!("{dir}/livelock-{k}.toml"), case.toml()).unwrap();
                Ok(())
            }
            None => check(case),
        }
    });
}
