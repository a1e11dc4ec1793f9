//! A ROS 2 robot's position uncertainty `σ` while it dead-reckons: what it
//! publishes (and its neighbours widen their radius by, `3(σ_i + σ_j)`,
//! [`echelon::safety::uncertainty_margin`]) when no EKF covariance says it
//! (no fixes, or `reset` fixes without a gate). docs/safety.md, "Uncertain
//! positions", states the rule; [`Drift`] keeps it.
//!
//! From the agent's odometry error model ([`ErrorModel`], the simulator's
//! Assumption 1 and Borenstein's errors), per odometry sample whose arc is
//! `(Δ, Θ)` (wheels `Δ_R,L = Δ ± l Θ`, each wheel's displacement variance
//! `v_R,L = slip |Δ_w| + tick²/6 + ζ²`,
//! [`ErrorModel::displacement_variance`]):
//!
//! - along the track, a random walk: `σ_a² += (v_R + v_L) / 4`;
//! - the heading, a random walk: `σ_θ² += (v_R + v_L) / (4 l²)`, and the
//!   position error it makes, at most `L += |Δ| σ_θ` (Minkowski: the
//!   standard deviation of a sum is at most the sum of theirs);
//! - the systematic heading error, a bound: `θ_s += |δ| |Δ| / (2l) + |1 −
//!   1/E_b| |Θ|` with `δ = 2(E_d − 1)/(E_d + 1)` (unequal wheels turn a
//!   straight line; a wrong wheelbase scales every turn), and the position
//!   error it makes, `B += |Δ| θ_s`.
//!
//! `σ = √(σ₀² + σ_a²) + L + B / 3`: one standard deviation of the random
//! errors plus a third of the systematic bound, so that the safety margin's
//! `3σ` covers the random errors to 99.7 % and the systematic ones fully.
//! `σ₀` (and the heading's `σ₀θ`, which `σ_θ` starts from) is 0 at the start
//! (the `odom_origin` is taken as exact) and a fix's noise after a `reset`
//! fix. Every term only grows with each sample, so `σ` is monotone in the
//! distance travelled, whatever the path; a perfect model gives 0.

use echelon::model::Pose;
use echelon::odometry::{ErrorModel, arc_motion};

/// The dead-reckoning uncertainty of one robot since its start or its last
/// fix (see the module doc).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Drift {
    errors: ErrorModel,
    /// `(l, r)`: half wheelbase and wheel radius, m.
    wheels: (f64, f64),
    /// `σ₀²`, m².
    base: f64,
    /// `σ_a²`, m².
    along: f64,
    /// `σ₀θ² + σ_θ²`, rad².
    heading: f64,
    /// `L`, m.
    lateral: f64,
    /// `θ_s`, rad.
    systematic_heading: f64,
    /// `B`, m.
    systematic: f64,
    /// The last raw odometry pose (odom frame).
    last: Option<Pose>,
}

impl Drift {
    /// No uncertainty yet, on odometry that errs as `errors` with wheels
    /// `(l, r)` (half wheelbase, wheel radius, m).
    pub fn new(errors: ErrorModel, wheels: (f64, f64)) -> Drift {
        Drift {
            errors,
            wheels,
            base: 0.0,
            along: 0.0,
            heading: 0.0,
            lateral: 0.0,
            systematic_heading: 0.0,
            systematic: 0.0,
            last: None,
        }
    }

    /// The next raw odometry pose (odom frame, heading unwrapped): the arc
    /// from the last one grows the uncertainty.
    pub fn on_odom(&mut self, raw: Pose) {
        let Some(prev) = self.last.replace(raw) else {
            return;
        };
        let (delta, big_theta) = arc_motion(&prev, &raw);
        let (l, r) = self.wheels;
        let [vr, vl] = self
            .errors
            .displacement_variance(r, [delta + l * big_theta, delta - l * big_theta]);
        let travel = delta.abs();
        self.along += 0.25 * (vr + vl);
        self.heading += 0.25 * (vr + vl) / (l * l);
        self.lateral += travel * self.heading.sqrt();
        let e = self.errors.wheel_diameter_ratio();
        let curvature = (2.0 * (e - 1.0) / (e + 1.0)).abs() / (2.0 * l);
        let scale = (1.0 - 1.0 / self.errors.wheelbase_ratio()).abs();
        self.systematic_heading += curvature * travel + scale * big_theta.abs();
        self.systematic += travel * self.systematic_heading;
    }

    /// A fix replaced the estimate: the uncertainty is the fix's, per
    /// position coordinate `position` m and heading `heading` rad (`None`:
    /// the fix gave no heading, whose uncertainty then keeps growing).
    pub fn reset(&mut self, position: f64, heading: Option<f64>) {
        let heading = heading.map_or(self.heading, |h| h * h);
        *self = Drift {
            base: position * position,
            heading,
            last: self.last,
            ..Drift::new(self.errors, self.wheels)
        };
    }

    /// `σ`, m.
    pub fn sigma(&self) -> f64 {
        (self.base + self.along).sqrt() + self.lateral + self.systematic / 3.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use echelon::odometry::arc_update;
    use proptest::prelude::*;

    const WHEELS: (f64, f64) = (0.15, 0.05);

    fn model() -> impl Strategy<Value = ErrorModel> {
        (
            0.0..1e-3f64,
            0.9..1.1f64,
            0.9..1.1f64,
            proptest::option::of(100..5000u32),
            0.0..1e-4f64,
        )
            .prop_map(|(slip, ed, eb, ticks, zeta)| {
                ErrorModel::PERFECT
                    .with_slip(slip)
                    .and_then(|m| m.with_systematic(ed, eb))
                    .and_then(|m| m.with_ticks_per_rev(ticks))
                    .and_then(|m| m.with_zeta(zeta, Default::default()))
                    .unwrap_or_else(|e| panic!("{e}"))
            })
    }

    /// Arcs `(Δ, Θ)` of 20 ms samples: forward, backward, turning on the
    /// spot, reversing.
    fn path() -> impl Strategy<Value = Vec<(f64, f64)>> {
        proptest::collection::vec((-0.01..0.01f64, -0.05..0.05f64), 1..400)
    }

    /// `d` driven along `arcs` from `start` (sent first unless it is
    /// already there): σ after each.
    fn drive(d: &mut Drift, start: Pose, arcs: &[(f64, f64)]) -> Vec<f64> {
        let mut p = start;
        if d.last.is_none() {
            d.on_odom(p);
        }
        arcs.iter()
            .map(|&(delta, big_theta)| {
                p = arc_update(&p, delta, big_theta);
                d.on_odom(p);
                d.sigma()
            })
            .collect()
    }

    proptest! {
        /// σ never decreases along any path (forward, backward, turning),
        /// and grows when the robot travels on odometry that errs.
        #[test]
        fn sigma_is_monotone_in_distance_travelled(
            errors in model(), arcs in path(), x in -5.0..5.0f64, theta in -3.0..3.0f64,
        ) {
            let mut d = Drift::new(errors, WHEELS);
            let sigmas = drive(&mut d, Pose { x, y: -x, theta }, &arcs);
            for w in sigmas.windows(2) {
                prop_assert!(w[1] >= w[0], "{} then {}", w[0], w[1]);
            }
            // Any travel on an erring odometer leaves some uncertainty.
            let travelled: f64 = arcs.iter().map(|a| a.0.abs()).sum();
            if errors.slip() > 0.0 && travelled > 1e-3 {
                prop_assert!(d.sigma() > 0.0);
            }
        }

        /// A perfect odometer is never uncertain, whatever it drove.
        #[test]
        fn a_perfect_model_gives_zero(arcs in path()) {
            let mut d = Drift::new(ErrorModel::PERFECT, WHEELS);
            let sigmas = drive(&mut d, Pose::default(), &arcs);
            prop_assert!(sigmas.iter().all(|&s| s == 0.0));
        }

        /// After a fix σ is the fix's (its position noise) and grows from
        /// there as from the start: the same path after the fix gives what
        /// it gives from a start with that uncertainty.
        #[test]
        fn a_fix_resets_sigma_to_its_noise(
            errors in model(), before in path(), after in path(),
            noise in 0.0..0.05f64, heading in 0.0..0.05f64,
        ) {
            let mut d = Drift::new(errors, WHEELS);
            let end = {
                drive(&mut d, Pose::default(), &before);
                d.last.unwrap_or_default()
            };
            d.reset(noise, Some(heading));
            prop_assert!((d.sigma() - noise).abs() < 1e-15);
            let mut fresh = Drift { last: Some(end), ..Drift::new(errors, WHEELS) };
            fresh.reset(noise, Some(heading));
            let a = drive(&mut d, end, &after);
            let b = drive(&mut fresh, end, &after);
            prop_assert_eq!(a, b);
        }
    }

    /// The closed forms on a straight line: along-track slip alone is a
    /// random walk, `σ = √(slip d / 2)`; unequal wheels alone bend it,
    /// `B = κ d²/2` (the sum's exact value, `κ Σ_k k Δ² = κ Δ² n(n+1)/2`).
    #[test]
    fn straight_line_closed_forms() {
        let (n, step) = (500u32, 0.004);
        let d = f64::from(n) * step;
        let line: Vec<(f64, f64)> = (0..n).map(|_| (step, 0.0)).collect();
        let slip = ErrorModel::PERFECT.with_slip(2e-4).unwrap();
        let mut a = Drift::new(slip, WHEELS);
        drive(&mut a, Pose::default(), &line);
        // Slip also turns the heading: compare the along-track part.
        assert!(((a.base + a.along).sqrt() - (2e-4 * d / 2.0).sqrt()).abs() < 1e-12);
        let ed = 1.02;
        let bent = ErrorModel::systematic(ed, 1.0).unwrap();
        let mut b = Drift::new(bent, WHEELS);
        drive(&mut b, Pose::default(), &line);
        let kappa = 2.0 * (ed - 1.0) / (ed + 1.0) / (2.0 * WHEELS.0);
        let want = kappa * step * step * f64::from(n * (n + 1)) / 2.0;
        assert!(
            (3.0 * b.sigma() - want).abs() < 1e-12,
            "{} {want}",
            3.0 * b.sigma()
        );
    }
}
