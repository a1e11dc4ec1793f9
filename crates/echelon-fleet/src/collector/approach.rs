//! The fleet's closest approach ([`ApproachWatch`]): the simulator's
//! accumulator ([`Approach`]) fed the true states the robots publish.

use std::collections::BTreeMap;

use echelon::model::State;
use echelon::stats::{Approach, ClosestApproach};

/// Feeds an [`Approach`] with the robots' published (true) states.
///
/// Robots publish at their own instants, so states are matched in time: at
/// each state received (agent `k`, fleet time `t`), every other robot's
/// latest state whose time `t_j` is within one state `period` of `t`
/// (`|t − t_j| ≤ period`, older or newer) is moved to `t` along its own
/// speeds (`x += v cos θ·Δ`, `y += v sin θ·Δ`, `θ += ω·Δ`, `Δ = t − t_j`),
/// and the accumulator is shown all of them at `t`. Robots with no state
/// that recent are left out of that instant. The error on a distance is
/// that of one extrapolated point: exact for a straight line at constant
/// speed, at most `½·a·period²` for a point accelerating at most `a`, and
/// in any case at most the point's speed × `period` (what matching without
/// extrapolation would give).
#[derive(Debug, Clone)]
pub struct ApproachWatch {
    approach: Approach,
    period: f64,
    /// Each agent's (0-based) latest state and its time.
    latest: BTreeMap<usize, (f64, State)>,
}

/// `s` moved by `dt` along its own speeds (first order).
fn advance(s: &State, dt: f64) -> State {
    let (sin, cos) = s.theta.sin_cos();
    State {
        x: s.x + s.v * cos * dt,
        y: s.y + s.v * sin * dt,
        theta: s.theta + s.omega * dt,
        ..*s
    }
}

impl ApproachWatch {
    /// A watch filling `approach`, matching states at most `period` s apart
    /// (the robots' state period, `1 / control_rate`).
    pub fn new(approach: Approach, period: f64) -> ApproachWatch {
        ApproachWatch {
            approach,
            period,
            latest: BTreeMap::new(),
        }
    }

    /// Agent `agent`'s (1-based) true state `s` at fleet time `t`.
    pub fn on_state(&mut self, agent: u32, t: f64, s: &State) {
        let Some(i) = (agent as usize).checked_sub(1) else {
            return;
        };
        if i >= self.approach.agents() || !t.is_finite() {
            return;
        }
        self.latest.insert(i, (t, *s));
        // A relative margin so that states a float rounding over one period
        // apart still match.
        let window = self.period * (1.0 + 1e-9);
        let shown: Vec<(usize, State)> = self
            .latest
            .iter()
            .filter(|(_, (tj, _))| (t - tj).abs() <= window)
            .map(|(&j, (tj, sj))| (j, if j == i { *sj } else { advance(sj, t - tj) }))
            .collect();
        self.approach
            .record_some(t, shown.iter().map(|(j, s)| (*j, s)));
    }

    /// The closest approach so far (`None` until two robots were matched).
    pub fn report(&self) -> Option<ClosestApproach> {
        self.approach
            .paired()
            .then(|| self.approach.closest().clone())
    }
}
