//! A lone robot and one post: nothing else can hold it, so its filter must
//! lead it round the post to its slot, never hold it for ever. Randomized
//! over the drive (Table I torque robots with and without wheel torque
//! limits, ideal and lagged velocity bases), the post's size and place
//! across the reference line, the radius, the gain, and a start at rest on
//! the post's barrier heading past either side.
//!
//! The fleet found the case: `fleet up obstacle-slalom` left robot 1 at
//! rest on the second post's barrier, heading past its left side, for the
//! last 40 s. Its filter was breaking the deadlock by turning its desired
//! motion right, which pointed into the post; with no reverse (the speed
//! envelope) the QP's answer was zero, for ever. The monitor now turns the
//! other way after a second standing still (`safety/deadlock.rs`).
#![allow(clippy::unwrap_used)]

use echelon::scenario::{Overrides, Scenario};
use echelon::sim::{Frame, ObserverError};
mod common;

use common::env_or;
use proptest::prelude::*;
use proptest::test_runner::RngSeed;

/// The robot's drive.
#[derive(Debug, Clone, Copy)]
enum Kind {
    /// A Table I preset, with an optional wheel torque limit, N m.
    Torque(&'static str, Option<f64>),
    /// A velocity base preset under the kinematic law.
    Velocity(&'static str),
}

#[derive(Debug, Clone, Copy)]
struct Post {
    kind: Kind,
    /// The safety radius, m.
    radius: f64,
    /// The post's radius, m.
    r: f64,
    /// The post's centre across the reference line, m.
    across: f64,
    /// The filter's `γ`, 1/s.
    gain: f64,
    /// Where the robot's point starts on the post's barrier: its bearing
    /// from the post's centre, from straight behind (`−x`), rad.
    bearing: f64,
    /// The robot's heading at rest, rad.
    heading: f64,
    /// The reference's speed, m/s.
    speed: f64,
}

/// The robot's point is this far ahead of its wheel axle, m.
const L: f64 = 0.05;

/// The run's length, s.
const DURATION: f64 = 150.0;

impl Post {
    /// The post's centre.
    const CENTRE_X: f64 = 2.0;

    fn toml(&self) -> String {
        let d = self.r + self.radius + 0.005;
        let point = [
            Self::CENTRE_X - d * self.bearing.cos(),
            self.across + d * self.bearing.sin(),
        ];
        let start = [
            point[0] - L * self.heading.cos(),
            point[1] - L * self.heading.sin(),
        ];
        let mut s = String::from("name = \"post\"\n");
        match self.kind {
            Kind::Torque(preset, limit) => {
                s += &format!("[sim]\nduration = {DURATION}\ndt = 0.005\n[log]\ndt = 0.1\n");
                s += &format!(
                    "[control]\nlaw = \"complete\"\nke = 1.5\nkz = 10.0\nl = {L}\nlycomp = \"none\"\n"
                );
                s += &format!("[robots.r]\npreset = \"{preset}\"\n");
                if let Some(t) = limit {
                    s += &format!("torque_limit = {t}\n");
                }
            }
            Kind::Velocity(preset) => {
                s += &format!("[sim]\nduration = {DURATION}\ndt = 0.01\n[log]\ndt = 0.1\n");
                s += &format!(
                    "[control]\nlaw = \"kinematic\"\nke = 1.0\nl = {L}\nlycomp = \"none\"\n"
                );
                s += &format!("[robots.r]\ndrive = \"velocity\"\npreset = \"{preset}\"\n");
            }
        }
        // The slot, 0.3 m behind the reference, starts level with the point.
        s += &format!(
            "[reference.line]\nspeed = {}\nstart = {{ x = {}, y = 0.0, theta = 0.0 }}\n",
            self.speed,
            point[0] + 0.3
        );
        s += &format!(
            "[safety]\nradius = {}\ngain = {}\nrange = 1.5\nobstacles = [{{ x = {}, y = {}, r = {} }}]\n",
            self.radius,
            self.gain,
            Self::CENTRE_X,
            self.across,
            self.r
        );
        s += &format!(
            "[[agents]]\nrobot = \"r\"\nstart = {{ x = {}, y = {}, theta = {} }}\nleader = \"reference\"\noffset = {{ x = 0.3, y = 0.0 }}\n",
            start[0], start[1], self.heading
        );
        s
    }
}

/// What a run showed.
#[derive(Debug)]
struct Passed {
    /// The smallest clearance of the point from the post's edge, m.
    clearance: f64,
    /// ‖e‖ at the end, m.
    final_error: f64,
    /// Whether the filter held the robot at the end.
    deadlocked: bool,
    /// Deadlocks it started breaking.
    breaks: u64,
    /// A state that was not finite, or a run error.
    bad: Option<String>,
}

fn run(case: &Post) -> Passed {
    let src = case.toml();
    let scenario = Scenario::parse(&src, "post.toml", None).unwrap();
    let run = scenario
        .build(&Overrides::default())
        .unwrap_or_else(|e| panic!("{e}\n{src}"));
    let sim = &mut run.simulation();
    let mut seen = Passed {
        clearance: f64::INFINITY,
        final_error: f64::NAN,
        deadlocked: false,
        breaks: 0,
        bad: None,
    };
    let mut every = |f: &Frame<'_>| -> Result<(), ObserverError> {
        let s = f.states[0];
        let p = [s.x + L * s.theta.cos(), s.y + L * s.theta.sin()];
        let gap = (p[0] - Post::CENTRE_X).hypot(p[1] - case.across) - case.r;
        seen.clearance = seen.clearance.min(gap);
        if !s.is_finite() {
            seen.bad.get_or_insert(format!("t = {} s: {s:?}", f.t));
        }
        seen.final_error = f.outputs[0].e[0].hypot(f.outputs[0].e[1]);
        seen.deadlocked = f.safety[0].deadlocked;
        seen.breaks = f.safety[0].deadlock_breaks;
        Ok(())
    };
    if let Err(e) = sim.run(&mut every) {
        seen.bad.get_or_insert(e.to_string());
    }
    seen
}

fn posts() -> impl Strategy<Value = Post> {
    let kind = prop_oneof![
        Just(Kind::Torque("agent1", None)),
        Just(Kind::Torque("agent2", None)),
        (8.0..40.0f64).prop_map(|t| Kind::Torque("agent1", Some(t))),
        Just(Kind::Velocity("ideal")),
        Just(Kind::Velocity("turtlebot3-burger")),
        Just(Kind::Velocity("turtlebot4")),
        Just(Kind::Velocity("jackal")),
    ];
    (
        kind,
        (0.1..0.35f64, 0.05..0.4f64, -1.0..1.0f64, 0.5..3.0f64),
        (-1.2..1.2f64, -1.2..1.2f64, 0.05..0.2f64),
    )
        .prop_map(
            |(kind, (radius, r, across, gain), (bearing, heading, speed))| Post {
                kind,
                radius,
                r,
                // Across the line within the post: the reference runs through it.
                across: across * r,
                gain,
                bearing,
                heading,
                speed,
            },
        )
}

fn check(case: &Post) -> Result<(), TestCaseError> {
    let seen = run(case);
    let src = case.toml();
    prop_assert!(seen.bad.is_none(), "{seen:?}\n{src}");
    prop_assert!(seen.clearance >= case.radius - 1e-3, "{seen:?}\n{src}");
    prop_assert!(
        seen.final_error < 0.01 && !seen.deadlocked,
        "held by a lone post: {seen:?}\n{src}"
    );
    Ok(())
}

proptest! {
    // A fixed seed, so CI runs the same sample (POST_CASES=N for more,
    // POST_SEED=K for another).
    #![proptest_config(ProptestConfig {
        cases: env_or("POST_CASES", 32) as u32,
        rng_seed: RngSeed::Fixed(env_or("POST_SEED", 7)),
        failure_persistence: None,
        ..ProptestConfig::default()
    })]

    /// A lone robot at rest on a post's barrier reaches its slot beyond
    /// the post, its point never more than 1 mm inside the radius.
    #[test]
    fn a_lone_robot_gets_round_a_post(case in posts()) {
        check(&case)?;
    }
}

/// The fleet's case: a Table I `agent1` at rest on obstacle-slalom's second
/// post (r = 0.2 m, 8 cm right of the line, radius 0.15 m, γ = 2/s), its
/// point 0.35 m from the centre 12° left of straight behind, heading 14°
/// left, as `fleet up obstacle-slalom` left robot 1 from t = 22 s on.
#[test]
fn the_fleets_obstacle_slalom_stand_still_is_broken() {
    let case = Post {
        kind: Kind::Torque("agent1", None),
        radius: 0.15,
        r: 0.2,
        across: -0.08,
        gain: 2.0,
        bearing: 0.21,
        heading: 0.247,
        speed: 0.15,
    };
    let seen = run(&case);
    assert!(seen.bad.is_none(), "{seen:?}");
    assert!(seen.clearance >= case.radius - 1e-3, "{seen:?}");
    assert!(seen.final_error < 0.01 && !seen.deadlocked, "{seen:?}");
    assert!(seen.breaks >= 1, "it had to break a deadlock: {seen:?}");
}

/// `POST_SURVEY=N cargo test --test safety_posts -- --ignored survey`: N
/// cases, every failure listed (the proptest stops at the first).
#[test]
#[ignore = "a survey for development: many cases"]
fn survey() {
    common::survey(posts(), env_or("POST_SURVEY", 200), |_, case| check(case));
}
