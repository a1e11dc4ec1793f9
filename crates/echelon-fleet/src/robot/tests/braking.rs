//! Cooperative braking on the fake clock: in a random formation of
//! TurtleBot 4s under the safety filter, one robot (at random) stops at a
//! random time — its leader stream cut (it settles onto the last
//! reference, its filter still on), or its odometry frozen (its watchdog
//! holds it: zero command, `held`, no share of any barrier) — while the
//! others drive on: nobody drives into it. The closest approach of any
//! two robots' points `l` ahead, from their true states every 10 ms,
//! stays above the safety radius (less the filter's 1 mm discretisation
//! tolerance; for a frozen odometry, less how far the held robot moves
//! unseen: `v·(t_detect + τ_v) + v²/2a`, its pose being unknown to everyone
//! meanwhile).

use proptest::prelude::*;

use super::*;

/// The safety radius between the points `l` ahead, m.
const RADIUS: f64 = 0.3;
/// The control law's `l`, m.
const L: f64 = 0.05;

/// `n` TurtleBot 4s behind a straight line at 0.15 m/s, robot `i` at
/// offset `offsets[i]` (behind, right of the reference), on its slot.
fn formation(offsets: &[(f64, f64)]) -> Scenario {
    let mut text = crate::testing::tb4_kinematic("braking", L);
    text += &format!(
        r#"[reference.line]
speed = 0.15
start = {{ x = 0.0, y = 0.0, theta = 0.0 }}
[safety]
radius = {RADIUS}
gain = 1.0
range = 1.5
[fleet]
control_rate = 50.0
link_timeout = 0.2
link_loss = {{ policy = "stop" }}
"#
    );
    for (i, (x, y)) in offsets.iter().enumerate() {
        text += &format!(
            "[[agents]]\nname = \"r{i}\"\nrobot = \"tb4\"\nstart = {{ x = {}, y = {}, theta = 0.0 }}\nleader = \"reference\"\noffset = {{ x = {x}, y = {y} }}\n",
            -x, -y
        );
    }
    Scenario::parse(&text, "braking", None).unwrap_or_else(|e| panic!("{e}\n{text}"))
}

/// Offsets on a grid `rows × cols`, `spacing` apart, each jittered.
fn grid() -> impl Strategy<Value = Vec<(f64, f64)>> {
    (2usize..=3, 1usize..=2, 0.45..0.8f64)
        .prop_flat_map(|(rows, cols, spacing)| {
            let n = rows * cols;
            (
                Just((rows, cols, spacing)),
                proptest::collection::vec((-0.05..0.05f64, -0.05..0.05f64), n),
            )
        })
        .prop_map(|((rows, cols, spacing), jitter)| {
            (0..rows * cols)
                .map(|i| {
                    let (r, c) = (i / cols, i % cols);
                    let (jx, jy) = jitter[i];
                    (
                        0.3 + r as f64 * spacing + jx,
                        (c as f64 - (cols as f64 - 1.0) / 2.0) * spacing + jy,
                    )
                })
                .collect()
        })
}

/// The formation of `offsets` with robot `k` under `fault`, run to `end`
/// on the fake clock: the closest approach of any two robots' points `l`
/// ahead, from their true states every 10 ms, and the fleet at the end.
fn closest_approach(offsets: &[(f64, f64)], k: usize, fault: FaultSpec, end: f64) -> (f64, Fleet) {
    let s = formation(offsets);
    let n = offsets.len();
    let faults: Vec<FaultSpec> = (0..n)
        .map(|i| if i == k { fault } else { FaultSpec::default() })
        .collect();
    let mut fleet = Fleet::of(&s, &faults);
    let closest = fleet.closest_until(end, L);
    (closest, fleet)
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]

    #[test]
    fn nobody_drives_into_a_robot_that_stops(
        offsets in grid(), pick in 0usize..6, at in 2.0..6.0f64, freeze in any::<bool>(),
    ) {
        let n = offsets.len();
        let k = pick % n;
        let fault = match freeze {
            true => FaultSpec { freeze_odometry: Some((at, 100.0)), ..FaultSpec::default() },
            false => FaultSpec { outage: Some((at, 100.0)), ..FaultSpec::default() },
        };
        let (v, tau, a, period) = (0.15, 0.1, 0.9, 0.02);
        let unseen = match freeze {
            true => v * (2.0 * period + period + tau) + v * v / (2.0 * a),
            false => 0.0,
        };
        let (closest, fleet) = closest_approach(&offsets, k, fault, at + 8.0);
        prop_assert!(
            closest >= RADIUS - 1e-3 - unseen,
            "closest {closest} (robot {} of {n}, at {at}, freeze {freeze}, {offsets:?})", k + 1
        );
        // A held robot commands zero: it is at rest. (One whose link was
        // cut settles onto the last reference under its filter, which
        // may still be making way for the others.)
        if freeze {
            let speed = fleet.robot(k).plant().true_state().v.abs();
            prop_assert!(speed < 1e-3, "robot {} still at {speed} m/s", k + 1);
            prop_assert_eq!(fleet.robot(k).last().link, LinkStatus::Held);
        }
    }
}

/// Two formations found by the property above where a robot whose leader
/// was cut, settling onto its last reference behind where it stood, had
/// used its 10 cm backup budget: the budget cut its filter's reverse
/// after the filter, its turn was kept, and it spun its point into the
/// robot behind it. The filter now certifies only what the budget allows
/// ([`echelon::agent::Guard::reverse`]).
#[test]
fn a_robot_out_of_backup_budget_keeps_its_share() {
    type Case<'a> = (&'a [(f64, f64)], usize, f64);
    let cases: [Case<'_>; 2] = [
        (
            &[
                (0.3309, -0.3779),
                (0.3, 0.3945),
                (1.0581, -0.4011),
                (1.0890, 0.3945),
            ],
            0,
            3.6805,
        ),
        (
            &[
                (0.3, -0.3747),
                (0.3, 0.3747),
                (1.0240, -0.3747),
                (1.0495, 0.3747),
                (1.7571, -0.3747),
                (1.7989, 0.3747),
            ],
            2,
            5.8374,
        ),
    ];
    for (offsets, k, at) in cases {
        let closest = closest_approach(
            offsets,
            k,
            FaultSpec {
                outage: Some((at, 100.0)),
                ..FaultSpec::default()
            },
            at + 8.0,
        )
        .0;
        assert!(
            closest >= RADIUS - 1e-3,
            "closest {closest} (robot {} of {})",
            k + 1,
            offsets.len()
        );
    }
}
