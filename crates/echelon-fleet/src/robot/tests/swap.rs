//! Everyone gets home in the fleet (issue trust2, item 4): the dense
//! encounters of the simulator's liveness test
//! ([`echelon::encounter::Swap`]: robots of one formation swapping slots
//! held in the reference's frame across a circle) run as robot tasks on the
//! fake clock — each robot's law and filter from what reaches it over the
//! bus (the leader's samples at 50 Hz, its neighbours' published states),
//! decentralised as on real robots; ideal velocity bases and Table I torque
//! robots. Every robot's published `‖e‖` is below
//! 1 cm from the bound on, and no two robots' points (their true states,
//! every 10 ms) come closer than the radius less 1 mm.

use proptest::prelude::*;

use super::*;
use echelon::encounter::{L, SETTLED, Swap, SwapDrive, SwapFrame};
use std::f64::consts::PI;

/// What a swap did in the fleet.
#[derive(Debug)]
struct Seen {
    /// The closest two robots' points came, m.
    closest: f64,
    /// The last time (fleet time) some robot published `‖e‖ ≥ SETTLED`, s.
    unsettled: f64,
    /// Each robot's last published `‖e‖`, m.
    finals: Vec<f64>,
}

fn fleet_of(swap: &Swap) -> (Scenario, Fleet) {
    let text = swap.toml()
        + "[fleet]\ncontrol_rate = 50.0\nreference_rate = 50.0\nlink_loss = { policy = \"stop\" }\n";
    let s = Scenario::parse(&text, "swap.toml", None).unwrap_or_else(|e| panic!("{e}\n{text}"));
    let fleet = Fleet::of(&s, &vec![FaultSpec::default(); swap.n()]);
    (s, fleet)
}

fn run(swap: &Swap) -> Seen {
    let (_, mut fleet) = fleet_of(swap);
    let n = swap.n();
    let end = swap.duration();
    let closest = fleet.closest_until(end, L);
    let mut unsettled = 0.0f64;
    let mut finals = vec![f64::INFINITY; n];
    for (i, last) in finals.iter_mut().enumerate() {
        for p in fleet.log(i) {
            let e = norm(p.state.e);
            if e >= SETTLED {
                unsettled = unsettled.max(p.state.t);
            }
            *last = e;
        }
    }
    Seen {
        closest,
        unsettled,
        finals,
    }
}

fn check(swap: &Swap) -> Result<(), TestCaseError> {
    let seen = run(swap);
    let limit = swap.bound();
    eprintln!(
        "{:?} N = {}: home at {:.1} s (bound {limit:.1} s), closest {:.4} m",
        swap.drive,
        swap.n(),
        seen.unsettled,
        seen.closest
    );
    let what = format!("{swap:?}: {seen:?}, bound {limit:.1} s");
    prop_assert!(seen.closest >= swap.radius - 1e-3, "radius: {what}");
    prop_assert!(seen.unsettled <= limit, "not home within the bound: {what}");
    prop_assert!(
        seen.finals.iter().all(|e| *e < SETTLED),
        "not home at the end: {what}"
    );
    Ok(())
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(8))]

    /// Velocity bases or Table I torque robots, 4–10 robots, antipodal or
    /// permuted, any radius and heading.
    #[test]
    fn everyone_gets_home_in_the_fleet(
        torque in any::<bool>(),
        n in 4usize..=10,
        radius in 0.15..0.3f64,
        k in 1.0..2.0f64,
        antipodal in any::<bool>(),
        perm in Just((0usize..10).collect::<Vec<_>>()).prop_shuffle(),
        speed in 0.02..0.1f64,
        heading in -PI..PI,
    ) {
        let to = if antipodal {
            (0..n).map(|i| (i + n / 2) % n).collect()
        } else {
            perm.into_iter().filter(|&i| i < n).collect()
        };
        check(&Swap {
            drive: if torque { SwapDrive::Torque } else { SwapDrive::Velocity },
            to,
            circle: k * Swap::smallest_circle(n, radius),
            radius,
            speed,
            heading,
            frame: SwapFrame::Leader,
        })?;
    }
}

/// The reported 8-robot swap (0.8 m circle, radius 0.22 m, 0.05 m/s), on
/// velocity bases and on Table I torque robots.
#[test]
fn the_reported_swap_in_the_fleet() {
    for drive in [SwapDrive::Velocity, SwapDrive::Torque] {
        let swap = Swap::antipodal(drive, 8, 0.8, 0.22, 0.05);
        check(&swap).unwrap_or_else(|e| panic!("{drive:?}: {e}"));
    }
}

/// A robot whose slot is in the leader's frame keeps the leader's last
/// heading when the leader's stream is cut and its link-loss policy
/// (`stop`) brings the leader to rest: the slots stay where they were (a
/// leader at rest has no heading of its own; the world's axes would swing
/// every slot about it, here by 2 rad, metres away).
#[test]
fn a_stopped_leader_keeps_its_heading() {
    let mut swap = Swap::antipodal(SwapDrive::Velocity, 4, 1.0, 0.2, 0.05);
    swap.heading = 2.0;
    let (_, mut fleet) = fleet_of(&swap);
    fleet.run_until(30.0);
    let at_cut: Vec<State> = fleet.robots().map(|r| r.plant().true_state()).collect();
    fleet.cut(30.0, 1e9);
    fleet.run_until(45.0);
    for (i, (r, before)) in fleet.robots().zip(&at_cut).enumerate() {
        let s = r.plant().true_state();
        let moved = (s.x - before.x).hypot(s.y - before.y);
        assert!(
            moved < 0.05,
            "robot {} moved {moved} m after the cut",
            i + 1
        );
        assert_eq!(r.last().link, LinkStatus::Stopping, "robot {}", i + 1);
    }
}
