//! Proptest strategies and checks shared by the velocity and torque
//! filters' tests.

use proptest::prelude::*;

use super::neighbour::{Neighbour, point};
use super::{Filtered, Outcome, SafetyConfig};
use crate::model::State;

/// The filter's `L` in the property tests, m.
pub(super) const L: f64 = 0.05;

/// The safety radius in the property tests, m.
const RADIUS: f64 = 0.3;

/// What a filter sees in the property tests: the robot, its neighbours
/// (outside the radius), and a configuration with some barrier gain.
#[derive(Debug, Clone)]
pub(super) struct Scene {
    pub(super) me: State,
    pub(super) ns: Vec<Neighbour>,
    pub(super) config: SafetyConfig,
}

/// A robot anywhere, neighbours outside the safety radius 0.3 around its
/// point `L` ahead, a barrier gain in `[0.2, 5)`.
pub(super) fn scene() -> impl Strategy<Value = Scene> {
    (state(), neighbours(), 0.2..5.0f64).prop_map(|(me, ns, gain)| Scene {
        ns: outside(&me, L, ns, RADIUS),
        me,
        config: SafetyConfig::new(RADIUS, gain, 1.5).expect("a gain in [0.2, 5) is valid"),
    })
}

fn state() -> impl Strategy<Value = State> {
    (
        -2.0..2.0f64,
        -2.0..2.0f64,
        -3.2..3.2f64,
        -0.5..0.5f64,
        -2.0..2.0f64,
    )
        .prop_map(|(x, y, theta, v, omega)| State {
            x,
            y,
            theta,
            v,
            omega,
        })
}

fn neighbours() -> impl Strategy<Value = Vec<Neighbour>> {
    prop::collection::vec((state(), any::<bool>()), 0..6).prop_map(|v| {
        v.into_iter()
            .map(|(s, coop)| Neighbour::of_state(&s, 0.05, Some([0.3, -0.2]), coop))
            .collect()
    })
}

/// Drops neighbours whose point is inside the radius (`h < 0`: the
/// filter starts outside the unsafe set).
fn outside(me: &State, l: f64, ns: Vec<Neighbour>, radius: f64) -> Vec<Neighbour> {
    let p = point(me, l);
    ns.into_iter()
        .filter(|n| (p[0] - n.p[0]).hypot(p[1] - n.p[1]) > radius)
        .collect()
}

/// The filter passed `nominal` on untouched (a diverged robot's, for the
/// divergence guard): outcome nominal, the command's two numbers (`numbers`:
/// `[u1, u2]` or `[v, ω]`) those of `nominal` bit for bit, NaN included.
pub(super) fn assert_passed<C: Copy>(
    out: &Filtered<C>,
    nominal: C,
    numbers: impl Fn(C) -> [f64; 2],
) {
    assert_eq!(out.outcome, Outcome::Nominal);
    let bits = |c| numbers(c).map(f64::to_bits);
    assert_eq!(bits(out.command), bits(nominal));
}
