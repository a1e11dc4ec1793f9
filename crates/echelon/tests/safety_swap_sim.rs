//! Liveness in the simulator (issue trust2, item 4): dense symmetric
//! encounters driven by the laws from a scenario, everyone gets home.
//!
//! `tests/safety_swap.rs` steps the filters by hand with a point-to-goal
//! controller, as a Python user does. Here the encounter is a formation
//! rearranging itself ([`echelon::encounter::Swap`]): every robot follows a
//! slow line reference, its slot — held in the reference's frame
//! (`offset = { x, y, frame = "leader" }`) — across a circle from where it
//! starts: the antipodal point or a random permutation of the starts. Each
//! robot's law (the kinematic law on velocity bases, the complete law,
//! eqs. 9–16, on Table I torque robots) drives its point through the crowd
//! to its slot, its own filter (`[safety]`) keeping the radius.
//!
//! The property: every robot's tracking error ‖e‖ is below 1 cm from
//! [`Swap::bound`] on (linear in the circle's size and in N), and no two
//! points come closer than the radius less 1 mm at any logged instant.
//!
//! The paper's own frame (eq. 7, the slot turning with the follower's
//! heading) does not get everyone home here: a robot at its slot pushed
//! sideways by a neighbour turns (its point 5 cm ahead moves 5 cm per
//! radian) and its slot, 1–5 m off, swings by that angle about the leader;
//! past ±π/2 it chases a slot mirrored ahead of the leader through the
//! crowd, and realigns only with the time constant `L_X / V_d` (43 s for
//! 2.6 m at 0.06 m/s): [`the_first_case_found_gets_home_in_the_leaders_frame`].
#![allow(clippy::unwrap_used)]

mod common;
use common::{Watched, fixed_sample};

use echelon::encounter::{SETTLED, Swap, SwapDrive, SwapFrame};
use proptest::prelude::*;
use std::f64::consts::PI;

fn run(case: &Swap) -> Watched {
    common::watch(&case.toml(), "swap.toml", SETTLED)
}

fn check(case: &Swap) -> Result<(), TestCaseError> {
    let seen = run(case);
    let limit = case.bound();
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

/// N 4–16 on a circle 1–2× the smallest they fit on, the antipodal swap or
/// a random permutation, radius 0.15–0.3 m, the reference at 0.02–0.1 m/s
/// at any heading.
fn cases(drive: SwapDrive) -> impl Strategy<Value = Swap> {
    (4usize..=16, 0.15..0.3f64, 1.0..2.0f64).prop_flat_map(move |(n, radius, k)| {
        let antipodal: Vec<usize> = (0..n).map(|i| (i + n / 2) % n).collect();
        let to = prop_oneof![
            Just(antipodal),
            Just((0..n).collect::<Vec<_>>()).prop_shuffle(),
        ];
        let circle = k * Swap::smallest_circle(n, radius);
        (to, 0.02..0.1f64, -PI..PI).prop_map(move |(to, speed, heading)| Swap {
            drive,
            to,
            circle,
            radius,
            speed,
            heading,
            frame: SwapFrame::Leader,
        })
    })
}

proptest! {
    #![proptest_config(fixed_sample(common::env_or("SWAP_SIM_CASES", 8) as u32, common::env_or("SWAP_SIM_SEED", 3)))]

    /// Velocity bases under the kinematic law: everyone home.
    #[test]
    fn everyone_gets_home_in_the_simulator_on_velocity_bases(case in cases(SwapDrive::Velocity)) {
        check(&case)?;
    }

    /// Table I torque robots under the complete law: everyone home.
    #[test]
    fn everyone_gets_home_in_the_simulator_on_torque_robots(case in cases(SwapDrive::Torque)) {
        check(&case)?;
    }
}

/// The reported swap in the simulator: 8 and 12 robots on a 0.8 m circle,
/// radius 0.22 m, both drives; needs at least one deadlock break.
#[test]
fn the_reported_swap_in_the_simulator() {
    for drive in [SwapDrive::Velocity, SwapDrive::Torque] {
        for n in [8, 12] {
            let case = Swap::antipodal(drive, n, 0.8, 0.22, 0.05);
            let seen = run(&case);
            eprintln!(
                "{drive:?} N = {n}: home at {:.1} s (bound {:.1} s), closest {:.4} m, {} breaks",
                seen.unsettled,
                case.bound(),
                seen.closest,
                seen.breaks
            );
            assert!(seen.bad.is_none(), "{case:?}: {seen:?}");
            assert!(seen.closest >= case.radius - 1e-3, "{case:?}: {seen:?}");
            assert!(seen.unsettled <= case.bound(), "{case:?}: {seen:?}");
            assert!(seen.breaks > 0, "{case:?}: {seen:?}");
        }
    }
}

/// The first case found failing in the paper's frame: velocity, 8 robots,
/// goals permuted [0,2,1,4,3,5,6,7] (two pairs swap, four hold), circle
/// 1.15 m, radius 0.265 m, the reference at 0.063 m/s along +x. In the
/// paper's frame a robot at its slot, pushed by a neighbour's keep-right
/// turn, swung past ±π/2 and chased a mirrored slot to the end (and with
/// today's filter still settles only after the bound, at 62 s, 30 breaks).
/// In the leader's frame everyone is home within it.
#[test]
fn the_first_case_found_gets_home_in_the_leaders_frame() {
    let case = Swap {
        drive: SwapDrive::Velocity,
        to: vec![0, 2, 1, 4, 3, 5, 6, 7],
        circle: 1.15,
        radius: 0.265,
        speed: 0.063,
        heading: 0.0,
        frame: SwapFrame::Leader,
    };
    check(&case).unwrap();
}
