//! An episode's draw: the leader's path, the slots and the robots' starts.

use std::f64::consts::PI;

use super::EnvConfig;
use crate::model::State;
use crate::reference::{Circle, Jet, Order, Trajectory};
use crate::rng::SplitMix64;
use crate::safety::point;

/// An environment's formation for one episode: the leader (a reference of
/// constant speed and turn rate) and each robot's `L_X`, `L_Y` (eq. 7).
#[derive(Debug, Clone)]
pub struct Slots {
    /// The virtual leader.
    pub leader: Circle,
    /// Robot `i`'s `L_X`, m (> 0: the leader ahead).
    pub lx: Vec<f64>,
    /// Robot `i`'s `L_Y`, m (the leader to its left when > 0).
    pub ly: Vec<f64>,
}

impl Default for Slots {
    fn default() -> Self {
        Slots {
            leader: Circle::new([0.0; 2], 0.0, 0.0, 0.0)
                .unwrap_or_else(|_| unreachable!("a circle at rest")),
            lx: Vec::new(),
            ly: Vec::new(),
        }
    }
}

impl Slots {
    /// The leader's `p_d`, `ṗ_d` at `t`.
    #[inline]
    pub fn leader_at(&self, t: f64) -> Jet {
        self.leader.eval(t, Order::Two)
    }
}

/// A seed for stream `k` of `seed`.
pub(super) fn mix(seed: u64, k: u64) -> u64 {
    SplitMix64::new(seed ^ k.wrapping_mul(0x9e37_79b9_7f4a_7c15)).next_u64()
}

/// How far a start may lie from its slot, in spacings.
const START_SPREAD: f64 = 0.2;
/// How far a slot may lie from its lattice point, in spacings.
const SLOT_JITTER: f64 = 0.15;
/// How far a start's heading may differ from the leader's, rad.
const HEADING_SPREAD: f64 = 0.5;

/// Draws an episode into `slots` and `starts` from `seed`: slots on a
/// lattice `spacing` apart behind the leader (`⌈√N⌉` wide), jittered and
/// shuffled; starts near the slots, at rest, their points at least the
/// radius apart when the draw allows it (20 tries, else the slots).
pub(super) fn draw(config: &EnvConfig, seed: u64, slots: &mut Slots, starts: &mut [State]) {
    let mut rng = SplitMix64::new(seed);
    let n = starts.len();
    let s = config.spacing;
    let heading = rng.uniform(-PI, PI);
    let speed = rng.uniform(config.speed.0, config.speed.1);
    let turn = rng.uniform(-config.turn, config.turn);
    slots.leader = Circle::new([0.0; 2], heading, speed, turn)
        .unwrap_or_else(|_| unreachable!("finite, speed ≥ 0"));
    let width = (n as f64).sqrt().ceil() as usize;
    slots.lx.clear();
    slots.ly.clear();
    for m in 0..n {
        let (row, col) = (m / width, m % width);
        let behind = (row as f64 + 1.0) * s + SLOT_JITTER * s * rng.uniform(-1.0, 1.0);
        let lateral = (col as f64 - 0.5 * (width as f64 - 1.0)) * s
            + SLOT_JITTER * s * rng.uniform(-1.0, 1.0);
        slots.lx.push(behind);
        slots.ly.push(-lateral);
    }
    // Fisher–Yates: robot i takes slot i after the shuffle.
    for i in (1..n).rev() {
        let j = (rng.next_u64() % (i as u64 + 1)) as usize;
        slots.lx.swap(i, j);
        slots.ly.swap(i, j);
    }
    let (sin, cos) = heading.sin_cos();
    let at_slot = |i: usize| {
        let (lx, ly) = (slots.lx[i], slots.ly[i]);
        State::at_rest(-(lx * cos - ly * sin), -(lx * sin + ly * cos), heading)
    };
    for _ in 0..20 {
        for (i, st) in starts.iter_mut().enumerate() {
            let r = START_SPREAD * s * rng.next_f64().sqrt();
            let a = rng.uniform(-PI, PI);
            let slot = at_slot(i);
            *st = State::at_rest(
                slot.x + r * a.cos(),
                slot.y + r * a.sin(),
                heading + rng.uniform(-HEADING_SPREAD, HEADING_SPREAD),
            );
        }
        if apart(starts, config.l, config.radius) {
            return;
        }
    }
    for (i, st) in starts.iter_mut().enumerate() {
        *st = at_slot(i);
    }
}

/// Whether every two robots' points are at least `radius` apart.
fn apart(states: &[State], l: f64, radius: f64) -> bool {
    states.iter().enumerate().all(|(i, a)| {
        let p = point(a, l);
        states[i + 1..].iter().all(|b| {
            let q = point(b, l);
            (p[0] - q[0]).hypot(p[1] - q[1]) >= radius
        })
    })
}
