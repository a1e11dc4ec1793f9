//! One case's run reduced: the largest values after the transient
//! ([`Peaks`]) and Theorem 2's bounds on them ([`theorem_bounds`]).

use super::{Case, Grid, SweepError, noise_free};
use crate::odometry::bound::{KinematicTheorem2, Theorem2};
use crate::safety::Outcome as FilterOutcome;
use crate::scenario::Scenario;
use crate::sim::{Frame, Simulation};

/// The largest values of one run after the transient (per agent, where
/// Theorem 2 bounds each agent), and the drift.
pub(super) struct Peaks {
    pub(super) z_max: Vec<f64>,
    pub(super) z_hat_max: f64,
    pub(super) drift: f64,
    pub(super) drift_max: f64,
    pub(super) e_max: Vec<f64>,
    pub(super) omega_max: Vec<f64>,
    /// Whether a velocity base's speed limits cut its command after the transient.
    pub(super) saturated: Vec<bool>,
    /// Whether a safety filter changed its command (or braked, or broke a
    /// deadlock) after the transient: that adds its own z, outside the theorem.
    pub(super) filtered: Vec<bool>,
}

impl Peaks {
    /// Nothing seen yet, for `n` agents.
    pub(super) fn new(n: usize) -> Peaks {
        Peaks {
            z_max: vec![0.0f64; n],
            z_hat_max: 0.0,
            drift: 0.0,
            drift_max: 0.0,
            e_max: vec![0.0f64; n],
            omega_max: vec![0.0f64; n],
            saturated: vec![false; n],
            filtered: vec![false; n],
        }
    }

    /// Takes in the dead-reckoning agents of frame `f`: the maxima once past
    /// `transient`, the final drift on the last frame.
    pub(super) fn observe(&mut self, f: &Frame<'_>, transient: f64) {
        for (i, odometer) in f.odometers.iter().enumerate() {
            let Some(odometer) = odometer else { continue };
            let (s, o) = (&f.states[i], &f.outputs[i]);
            let d = odometer.drift(s);
            if f.t >= transient {
                self.drift_max = self.drift_max.max(d);
                self.z_max[i] = self.z_max[i].max(o.z[0].hypot(o.z[1]));
                self.z_hat_max = self.z_hat_max.max(o.z_hat[0].hypot(o.z_hat[1]));
                self.e_max[i] = self.e_max[i].max(o.e[0].hypot(o.e[1]));
                self.omega_max[i] = self.omega_max[i].max(s.omega.abs());
                self.saturated[i] |= o.velocity.is_some_and(|v| v.saturated);
                self.filtered[i] |= f.safety.get(i).is_some_and(|s| {
                    s.enabled && (s.outcome != FilterOutcome::Nominal || s.deadlock)
                });
            }
            if f.last {
                self.drift = self.drift.max(d);
            }
        }
    }
}

/// Whether agent `i` of `sim` dead-reckons.
pub(super) fn dead_reckoning(sim: &Simulation, i: usize) -> bool {
    sim.odometers().get(i).is_some_and(Option::is_some)
}

/// Theorem 2's bounds over the agents it covers, the largest of each (`z`,
/// measured `z` or `e` over its bound, `e`), when it applies to the case.
pub(super) fn theorem_bounds(
    scenario: &Scenario,
    grid: &Grid,
    case: &Case,
    sim: &Simulation,
    peaks: &Peaks,
) -> Result<[Option<f64>; 3], SweepError> {
    let theorem_applies = !case.outside_assumption_1()
        && case.zeta > 0.0
        && case.fix_every > 0
        // `apply` keeps the noise settings, so the file's are the case's.
        && noise_free(scenario);
    let (mut z_bound, mut ratio, mut e_bound) = (None, None, None);
    let mut widen = |z: f64, r: f64, e: f64| {
        z_bound = Some(z_bound.map_or(z, |x: f64| x.max(z)));
        ratio = Some(ratio.map_or(r, |x: f64| x.max(r)));
        e_bound = Some(e_bound.map_or(e, |x: f64| x.max(e)));
    };
    if theorem_applies {
        for (i, a) in sim.agents().iter().enumerate() {
            if !dead_reckoning(sim, i) || peaks.filtered[i] {
                continue;
            }
            match a.velocity_robot() {
                None => {
                    let t = Theorem2::new(
                        a.gains().ke(),
                        a.gains().kz(),
                        case.zeta,
                        peaks.omega_max[i],
                        grid.0.gamma,
                    )?;
                    let b = t.z_bound(case.fix_every);
                    widen(b, peaks.z_max[i] / b, b / a.gains().ke());
                }
                // The kinematic form is for an ideal base: no lag, and no
                // speed limit cutting the command once the transient is over.
                Some(r)
                    if r.base().tau_v() == 0.0
                        && r.base().tau_omega() == 0.0
                        && !peaks.saturated[i] =>
                {
                    let t = KinematicTheorem2::new(a.gains().ke(), case.zeta, grid.0.gamma)?;
                    let e = t.e_bound(case.fix_every);
                    widen(t.z_bound(case.fix_every), peaks.e_max[i] / e, e);
                }
                Some(_) => {}
            }
        }
    }
    Ok([z_bound, ratio, e_bound])
}
