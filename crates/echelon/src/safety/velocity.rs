//! The filter for velocity bases: `ḣ ≥ −γ h`, linear in `(v, ω)`, within
//! the base's speed limits.

use super::filter::{Filtered, Own, SafetyFilter};
use super::neighbour::{Neighbour, Obstacle};
use super::qp::{Constraint, push_box, solve_relaxed};
use crate::base::{VelocityBase, VelocityCommand};
use crate::model::State;

impl SafetyFilter {
    /// Filters a velocity base's command `nominal` at time `t` (s) for a robot
    /// in state `me` (its point `l` ahead): `ḣ ≥ −γ h` for every neighbour in
    /// range and every obstacle, and the base's speed limits.
    #[allow(clippy::too_many_arguments)]
    pub fn velocity(
        &mut self,
        t: f64,
        me: &State,
        l: f64,
        nominal: VelocityCommand,
        base: &VelocityBase,
        neighbours: &[Neighbour],
        obstacles: &[Obstacle],
    ) -> Filtered<VelocityCommand> {
        let own = Own::ahead(me, l, 0.5 * self.period);
        let limited = base.limit(nominal).0;
        let x0 = [limited.v, l * limited.omega];
        let gamma = self.config.gain;
        self.rows.clear();
        let min_distance = self.barriers(&own, neighbours, obstacles, |d, h, n| {
            let a = own.row(d);
            let b = match n {
                Some(n) if n.cooperative => {
                    let shared = [own.dp[0] + n.dp[0], own.dp[1] + n.dp[1]];
                    -0.5 * gamma * h + d[0] * shared[0] + d[1] * shared[1]
                }
                Some(n) => -gamma * h + 2.0 * (d[0] * n.dp[0] + d[1] * n.dp[1]),
                None => -gamma * h,
            };
            Constraint { a, b }
        });
        let barriers = self.rows.len();
        push_box(&mut self.rows, [base.v_max(), l * base.omega_max()]);
        let decision = self.decide(t, x0, barriers, [0.0, 0.0]);
        let of = |x: [f64; 2]| VelocityCommand {
            v: x[0],
            omega: x[1] / l,
        };
        // No command satisfies every barrier within the box: the one that
        // breaks them least (one shared slack) within the base's limits, so
        // its neighbours' shares are missed as little as possible; zero if
        // even that fails.
        let braked =
            || solve_relaxed(&self.rows, barriers, x0).map_or(VelocityCommand::default(), of);
        Filtered::decided(decision, nominal, limited, min_distance, of, braked)
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use super::*;
    use crate::base::VelocityBaseSpec;
    use crate::safety::Outcome;
    use crate::safety::SafetyConfig;

    fn config() -> SafetyConfig {
        SafetyConfig::new(0.3, 1.0, 2.0).unwrap()
    }

    fn ideal() -> VelocityBase {
        VelocityBase::new(VelocityBaseSpec {
            v_max: 0.5,
            omega_max: 4.0,
            ..VelocityBase::IDEAL.spec()
        })
        .unwrap()
    }

    /// One call of a fresh filter on an ideal base at rest at the origin
    /// facing +x (its point 0.05 m ahead), with `nominal` and the one
    /// neighbour `other` (its point as far ahead of it).
    fn once(
        other: &State,
        cooperative: bool,
        nominal: VelocityCommand,
    ) -> Filtered<VelocityCommand> {
        let l = 0.05;
        let me = State::at_rest(0.0, 0.0, 0.0);
        let n = Neighbour::of_state(other, l, None, cooperative);
        SafetyFilter::new(config()).velocity(0.0, &me, l, nominal, &ideal(), &[n], &[])
    }

    #[test]
    fn a_nominal_that_is_safe_passes_unchanged() {
        // Driving away from a neighbour behind.
        let nominal = VelocityCommand { v: 0.3, omega: 0.1 };
        let out = once(&State::at_rest(-1.0, 0.0, 0.0), true, nominal);
        assert_eq!(out.outcome, Outcome::Nominal);
        assert_eq!(out.command, nominal);
    }

    #[test]
    fn head_on_the_filter_keeps_half_the_barrier() {
        let other = State::at_rest(0.6, 0.0, std::f64::consts::PI);
        let out = once(&other, true, VelocityCommand { v: 0.5, omega: 0.0 });
        assert_eq!(out.outcome, Outcome::Filtered);
        // d = p_i − p_j = (−0.5, 0), h = 0.25 − 0.09; 2 dᵀṗ = −v ≥ −h/2.
        let h = 0.25 - 0.09;
        assert!((out.command.v - h / 2.0).abs() < 1e-6, "{out:?}");
        assert!(out.command.omega.abs() < 1e-6);
        assert!((out.min_distance - 0.5).abs() < 1e-12);
    }

    #[test]
    fn boxed_in_it_flees_as_fast_as_its_base_allows() {
        // A non-cooperative neighbour rushing in faster than the base can flee.
        let mut other = State::at_rest(0.40, 0.0, std::f64::consts::PI);
        other.v = 3.0;
        let out = once(&other, false, VelocityCommand { v: 0.1, omega: 0.0 });
        assert_eq!(out.outcome, Outcome::Braked);
        // The least violation within |v| ≤ 0.5: full speed straight back.
        assert!((out.command.v + 0.5).abs() < 1e-6, "{out:?}");
        assert!(out.command.omega.abs() < 1e-4, "{out:?}");
    }

    mod properties {
        use super::*;
        use crate::safety::strategies::{L, Scene, scene};
        use crate::safety::{Obstacle, TOLERANCE};
        use proptest::prelude::*;

        /// `x` of the QP for a velocity command.
        fn x_of(c: VelocityCommand, l: f64) -> [f64; 2] {
            [c.v, l * c.omega]
        }

        proptest! {
            /// The filtered command satisfies every constraint given to the
            /// QP (within [`TOLERANCE`], clarabel's default tolerances 1e-8),
            /// or the robot brakes; a nominal that satisfies them all comes
            /// back bit for bit.
            #[test]
            fn velocity_filter_satisfies_its_constraints(
                Scene { me, ns, config } in scene(),
                v in -0.8..0.8f64,
                omega in -3.0..3.0f64,
            ) {
                let obstacles = [Obstacle::new(1.5, -1.5, 0.2).unwrap()];
                let mut f = SafetyFilter::new(config);
                let base = ideal();
                let nominal = VelocityCommand { v, omega };
                let out = f.velocity(0.0, &me, L, nominal, &base, &ns, &obstacles);
                let limited = base.limit(nominal).0;
                let rows = f.constraints().to_vec();
                let nominal_ok = rows.iter().all(|c| c.slack(x_of(limited, L)) >= 0.0);
                match out.outcome {
                    Outcome::Nominal => {
                        prop_assert!(nominal_ok);
                        prop_assert_eq!(out.command, limited);
                    }
                    Outcome::Filtered => {
                        prop_assert!(!nominal_ok);
                        let x = x_of(out.command, L);
                        for c in &rows {
                            prop_assert!(c.slack(x) >= -TOLERANCE, "{c:?} at {x:?}");
                        }
                    }
                    Outcome::Braked => {
                        // Within the base's limits, and breaking the
                        // barriers no more than standing still would.
                        let x = x_of(out.command, L);
                        // (clarabel's tolerance, in x = (v, L ω))
                        prop_assert!(out.command.v.abs() <= base.v_max() + TOLERANCE);
                        prop_assert!(L * out.command.omega.abs() <= L * base.omega_max() + TOLERANCE);
                        let worst = |x: [f64; 2]| {
                            rows.iter().map(|c| -c.slack(x)).fold(0.0f64, f64::max)
                        };
                        prop_assert!(worst(x) <= worst([0.0; 2]) + 1e-6, "{x:?}");
                    }
                }
                if nominal_ok {
                    prop_assert_eq!(out.outcome, Outcome::Nominal);
                }
            }
        }
    }
}
