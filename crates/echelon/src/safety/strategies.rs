//! Proptest strategies shared by the velocity and torque filters' property
//! tests.

use proptest::prelude::*;

use super::neighbour::{Neighbour, point};
use crate::model::State;

pub(super) fn state() -> impl Strategy<Value = State> {
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

pub(super) fn neighbours() -> impl Strategy<Value = Vec<Neighbour>> {
    prop::collection::vec((state(), any::<bool>()), 0..6).prop_map(|v| {
        v.into_iter()
            .map(|(s, coop)| Neighbour::of_state(&s, 0.05, Some([0.3, -0.2]), coop))
            .collect()
    })
}

/// Drops neighbours whose point is inside the radius (`h < 0`: the
/// filter starts outside the unsafe set).
pub(super) fn outside(me: &State, l: f64, ns: Vec<Neighbour>, radius: f64) -> Vec<Neighbour> {
    let p = point(me, l);
    ns.into_iter()
        .filter(|n| (p[0] - n.p[0]).hypot(p[1] - n.p[1]) > radius)
        .collect()
}
