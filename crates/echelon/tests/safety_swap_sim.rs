//! Liveness in the simulator (issue trust2, item 4): dense symmetric
//! encounters driven by the paper's laws from a scenario, everyone gets
//! home.
//!
//! `tests/safety_swap.rs` steps the filters by hand with a point-to-goal
//! controller, as a Python user does. Here the encounter is a formation:
//! every robot follows a slow line reference (`leader = "reference"`) and
//! its slot, the offset, lies across a circle from where it starts — the
//! antipodal point, or a random permutation of the starts. Each robot's
//! law (the kinematic law on velocity bases, the complete law, eqs. 9–13,
//! on Table I torque robots) drives its point through the crowd to the
//! slot, its own filter (`[safety]`) keeping the radius. At the start every
//! robot faces along the reference, so its slot is where the offset puts it
//! in the reference's frame; while it turns to cross, the slot turns with
//! its heading (eq. 7 is written in the follower's frame), and it settles
//! there once it faces along the reference again.
//!
//! The property: every robot's tracking error ‖e‖ (eq. 7) is below 1 cm from
//! the bound [`bound`] on (linear in the circle's size and in N), and no
//! two points come closer than the radius less 1 mm at any logged instant.
#![allow(clippy::unwrap_used)]

mod common;
use common::{Watched, fixed_sample};

use proptest::prelude::*;
use std::f64::consts::PI;

/// The robots' point ahead of the axle, m.
const L: f64 = 0.05;

/// Settled: ‖e‖ below this, m.
const SETTLED: f64 = 0.01;

/// The drive of every robot of a case.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Drive {
    /// An ideal velocity base (0.5 m/s, 3 rad/s), the kinematic law.
    Velocity,
    /// Table I's agent 1 (eq. 3), the complete law.
    Torque,
}

#[derive(Debug, Clone)]
struct Case {
    drive: Drive,
    /// Robot `i` goes to robot `to[i]`'s start across the circle.
    to: Vec<usize>,
    /// The circle's radius, m.
    circle: f64,
    /// The safety radius, m.
    radius: f64,
    /// The reference's speed (m/s) and heading (rad).
    speed: f64,
    heading: f64,
}

impl Case {
    fn n(&self) -> usize {
        self.to.len()
    }

    /// Robot `i`'s start in the reference's frame at t = 0 (x ahead, y
    /// left): on a circle whose centre is `circle + 1` m behind the
    /// reference.
    fn at(&self, i: usize) -> [f64; 2] {
        let (s, c) = (2.0 * PI * i as f64 / self.n() as f64).sin_cos();
        [-(self.circle + 1.0) + self.circle * c, self.circle * s]
    }

    /// The farthest a robot's slot lies from its start, m.
    fn farthest(&self) -> f64 {
        (0..self.n())
            .map(|i| {
                let (a, b) = (self.at(i), self.at(self.to[i]));
                (a[0] - b[0]).hypot(a[1] - b[1])
            })
            .fold(0.0, f64::max)
    }

    fn toml(&self) -> String {
        let mut s = String::from("name = \"swap\"\n");
        match self.drive {
            Drive::Velocity => {
                s += &format!("[sim]\nduration = {}\ndt = 0.01\n", self.duration());
                s += &format!(
                    "[control]\nlaw = \"kinematic\"\nke = 1.0\nl = {L}\nlycomp = \"none\"\n"
                );
                s += "[robots.r]\ndrive = \"velocity\"\npreset = \"ideal\"\nv_max = 0.5\nomega_max = 3.0\n";
            }
            Drive::Torque => {
                s += &format!("[sim]\nduration = {}\ndt = 0.005\n", self.duration());
                s += &format!(
                    "[control]\nlaw = \"complete\"\nke = 1.5\nkz = 10.0\nl = {L}\nlycomp = \"none\"\n"
                );
                s += "[robots.r]\npreset = \"agent1\"\n";
            }
        }
        s += "[log]\ndt = 0.05\n";
        s += &format!(
            "[reference.line]\nspeed = {}\nstart = {{ x = 0.0, y = 0.0, theta = {} }}\n",
            self.speed, self.heading
        );
        s += &format!("[safety]\nradius = {}\ngain = 1.0\n", self.radius);
        let (sin, cos) = self.heading.sin_cos();
        for i in 0..self.n() {
            let p = self.at(i);
            let w = [p[0] * cos - p[1] * sin, p[0] * sin + p[1] * cos];
            // The slot: the point `−offset` from the reference, in its frame.
            let g = self.at(self.to[i]);
            s += &format!(
                "[[agents]]\nrobot = \"r\"\nstart = {{ x = {}, y = {}, theta = {} }}\nleader = \"reference\"\noffset = {{ x = {}, y = {} }}\n",
                w[0] - L * cos,
                w[1] - L * sin,
                self.heading,
                -g[0],
                -g[1]
            );
        }
        s
    }

    /// The run's length: the bound and 10 s to show the robots stay.
    fn duration(&self) -> f64 {
        (bound(self) + 10.0).ceil()
    }
}

/// The settling bound, s:
///
/// ```text
/// T ≤ farthest / s + ln(s / (k SETTLED)) / k + N · 2 radius / s + 20 s
/// ```
///
/// with `s = 0.15 m/s` the point speed the law keeps to across the crowd
/// (the filter's `γ` times the gaps it sees: robots within a few radii of
/// each other close at ~0.1–0.2 m/s) and `k = 1/s` its gain (`ke`): a free
/// robot's run and its exponential approach, a robot's diameter of detour
/// per robot it may have to go round, and 20 s for the deadlock monitor and
/// the turns (a robot faces away from the reference while it crosses and
/// turns back at the slot). Linear in the circle's size and in N.
fn bound(case: &Case) -> f64 {
    let s = 0.15;
    let k = 1.0;
    case.farthest() / s
        + (s / (k * SETTLED)).ln() / k
        + case.n() as f64 * 2.0 * case.radius / s
        + 20.0
}

fn run(case: &Case) -> Watched {
    common::watch(&case.toml(), "swap.toml", SETTLED)
}

fn check(case: &Case) -> Result<(), TestCaseError> {
    let seen = run(case);
    let limit = bound(case);
    let what = format!("{case:?}: {seen:?}, bound {limit:.1} s");
    prop_assert!(seen.bad.is_none(), "{what}");
    prop_assert!(seen.closest >= case.radius - 1e-3, "radius: {what}");
    prop_assert!(seen.unsettled <= limit, "not home within the bound: {what}");
    prop_assert!(
        seen.finals.iter().all(|e| *e < SETTLED),
        "not home at the end: {what}"
    );
    Ok(())
}

/// N 4–16 on a circle 1–2× the smallest they fit on (a diameter each
/// around it, 10 % to spare), the antipodal swap or a random permutation,
/// radius 0.15–0.3 m, the reference at 0.02–0.1 m/s at any heading.
fn cases(drive: Drive) -> impl Strategy<Value = Case> {
    (4usize..=16, 0.15..0.3f64, 1.0..2.0f64).prop_flat_map(move |(n, radius, k)| {
        let antipodal: Vec<usize> = (0..n).map(|i| (i + n / 2) % n).collect();
        let to = prop_oneof![
            Just(antipodal),
            Just((0..n).collect::<Vec<_>>()).prop_shuffle(),
        ];
        let circle = k * 1.1 * n as f64 * 2.0 * radius / (2.0 * PI);
        (to, 0.02..0.1f64, -PI..PI).prop_map(move |(to, speed, heading)| Case {
            drive,
            to,
            circle,
            radius,
            speed,
            heading,
        })
    })
}

// OPEN (issue trust2, item 4, "in the simulator"): these fail, and are
// ignored until the cause below is fixed; `cargo test -p echelon --test
// safety_swap_sim -- --ignored` shows them. The filters stepped by hand
// with a point-to-goal controller (tests/safety_swap.rs) get everyone home;
// under the formation laws they do not. Found on the first run:
// - velocity, 8 robots, goals permuted [0,2,1,4,3,5,6,7] (two pairs swap,
//   four hold), circle 1.15 m, radius 0.265 m, reference 0.063 m/s along
//   +x: robot 5 is at its slot (‖e‖ < 1 mm) from t = 8 s; at t = 28 s a
//   neighbour's keep-right turn pushes it, its heading swings past ±π/2
//   (t = 36 s), and since the slot is held in the follower's own frame
//   (eq. 7) a robot facing backwards chases a slot mirrored ahead of the
//   leader: ‖e‖ 4–7 m to the end (67 s), the filter holding it at
//   0.01 m/s among the others;
// - velocity, the reported 8-robot antipodal swap (0.8 m circle, 0.22 m,
//   0.05 m/s): robot 7 0.91 m off at 67 s, 27 breaks;
// - torque, 4 robots, circle 0.30 m, radius 0.15 m: home, but at 41.5 s
//   against a bound of 34.8 s.
// The radius held in every case (closest 0.1503 vs 0.15; 0.22022 vs 0.22).
proptest! {
    #![proptest_config(fixed_sample(common::env_or("SWAP_SIM_CASES", 8) as u32, common::env_or("SWAP_SIM_SEED", 3)))]

    /// Velocity bases under the kinematic law: everyone home.
    #[test]
    #[ignore = "open: robots pushed off their slots turn backwards and chase a mirrored slot (see OPEN above)"]
    fn everyone_gets_home_in_the_simulator_on_velocity_bases(case in cases(Drive::Velocity)) {
        check(&case)?;
    }

    /// Table I torque robots under the complete law: everyone home.
    #[test]
    #[ignore = "open: a 4-robot swap home 7 s after the bound (see OPEN above)"]
    fn everyone_gets_home_in_the_simulator_on_torque_robots(case in cases(Drive::Torque)) {
        check(&case)?;
    }
}

/// The reported swap in the simulator: 8 and 12 robots on a 0.8 m circle,
/// radius 0.22 m, both drives; needs at least one deadlock break.
#[test]
#[ignore = "open: robot 7 of the velocity swap ends 0.91 m off (see OPEN above)"]
fn the_reported_swap_in_the_simulator() {
    for drive in [Drive::Velocity, Drive::Torque] {
        for n in [8, 12] {
            let case = Case {
                drive,
                to: (0..n).map(|i| (i + n / 2) % n).collect(),
                circle: 0.8,
                radius: 0.22,
                speed: 0.05,
                heading: 0.0,
            };
            let seen = run(&case);
            assert!(seen.bad.is_none(), "{case:?}: {seen:?}");
            assert!(seen.closest >= case.radius - 1e-3, "{case:?}: {seen:?}");
            assert!(seen.unsettled <= bound(&case), "{case:?}: {seen:?}");
            assert!(seen.breaks > 0, "{case:?}: {seen:?}");
        }
    }
}
