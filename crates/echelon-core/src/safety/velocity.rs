//! The filter for velocity bases: without lag `ḣ ≥ −γ h`, linear in
//! `(v, ω)`, within the base's speed limits; with a lag on either axis the
//! exponential barrier of relative degree two (as for torques, `filter.rs`)
//! on the lags' rates, the speed envelope ([`Envelope`]), and the base's
//! speed and acceleration limits as hard rows.

use super::filter::{EMERGENCY_ACCEL, Envelope, Filtered, Own, SafetyFilter, Speed};
use super::neighbour::{Neighbour, Obstacle};
use super::qp::{Constraint, push_band, push_box, solve_relaxed};
use crate::model::State;
use crate::model::base::{VelocityBase, VelocityCommand};

/// The lag, s, a velocity base's lag-free axis is taken to have when the
/// other axis lags and the filter runs continuously (no period): its speed
/// jumps to the command, which the barrier of relative degree two sees as a
/// lag this short. With a controller period `T` the axis's lag is taken as
/// `T` (the speed reaches the held command within one period; see
/// `SafetyFilter::held_lag`).
pub const STEP_LAG: f64 = 0.01;

/// What [`SafetyFilter::velocity`] was given, handed on to the lagged
/// base's filter.
#[derive(Debug, Clone, Copy)]
struct Call<'a> {
    t: f64,
    me: &'a State,
    l: f64,
    nominal: VelocityCommand,
    base: &'a VelocityBase,
    neighbours: &'a [Neighbour],
    obstacles: &'a [Obstacle],
}

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
        if !(me.is_finite() && nominal.v.is_finite() && nominal.omega.is_finite()) {
            // Diverged: the non-finite value goes on for the divergence
            // guard to report (`crate::sim::guard`), no QP on it.
            return Filtered::passed(nominal);
        }
        if base.tau_v() > 0.0 || base.tau_omega() > 0.0 {
            return self.lagged(Call {
                t,
                me,
                l,
                nominal,
                base,
                neighbours,
                obstacles,
            });
        }
        let own = Own::ahead(me, l, 0.5 * self.period);
        let limited = self.reversing(base.limit(nominal).0);
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
        self.push_reverse();
        let decision = self.decide(t, x0, barriers, [0.0, 0.0], Speed::Command);
        let of = |x: [f64; 2]| VelocityCommand {
            v: x[0],
            omega: x[1] / l,
        };
        // No command satisfies every barrier within the box: the one that
        // breaks its neighbours' rows least (one shared slack) within the
        // base's limits and clear of every obstacle, so its neighbours'
        // shares are missed as little as possible and nothing is pushed
        // into what cannot move out of the way (a robot squeezed between a
        // neighbour and an obstacle crept into the obstacle by 9 mm at 50 ms
        // steps when its rows shared the slack) — if it breaks no barrier
        // more than standing still would (it may, from inside an obstacle's
        // radius); else the one that breaks every barrier least; zero if
        // even that fails. The obstacles' rows come after the neighbours'
        // ([`SafetyFilter::barriers`]).
        let neighbour_rows = barriers - obstacles.len();
        let braked = || {
            let worst = |x: [f64; 2]| {
                self.rows[..barriers]
                    .iter()
                    .map(|c| -c.slack(x))
                    .fold(0.0f64, f64::max)
            };
            solve_relaxed(&self.rows, neighbour_rows, x0)
                .filter(|&x| worst(x) <= worst([0.0; 2]))
                .or_else(|| solve_relaxed(&self.rows, barriers, x0))
                .map_or(VelocityCommand::default(), of)
        };
        Filtered::decided(decision, nominal, limited, min_distance, of, braked)
    }

    /// `cmd` with its backward speed within the base's reverse cap
    /// ([`SafetyFilter::set_reverse_cap`]).
    #[inline]
    fn reversing(&self, cmd: VelocityCommand) -> VelocityCommand {
        VelocityCommand {
            v: cmd.v.max(-self.reverse),
            ..cmd
        }
    }

    /// The hard row `v ≥ −cap` of a finite reverse cap.
    #[inline]
    fn push_reverse(&mut self) {
        if self.reverse.is_finite() {
            self.rows.push(Constraint {
                a: [1.0, 0.0],
                b: -self.reverse,
            });
        }
    }

    /// The lag `τ` (s, 0: none) as the filter sees it when the command is
    /// held for the period `T`: the lag whose rate `(x − v)/τ'` is the
    /// speed's mean rate over the period, `τ' = T / (1 − e^{−T/τ})`
    /// (`≈ τ + T/2`; `T` for an axis without lag, whose speed steps to the
    /// command). Without a period, `τ` (a lag-free axis: [`STEP_LAG`]).
    fn held_lag(&self, tau: f64) -> f64 {
        let t = self.period;
        match (t > 0.0, tau > 0.0) {
            (true, _) => t / -(-t / tau).exp_m1(),
            (false, true) => tau,
            (false, false) => STEP_LAG,
        }
    }

    /// [`SafetyFilter::velocity`] for a base with a lag on either axis: the
    /// command `x = (v*, L ω*)` moves the speeds only through the lags,
    /// `v̇ = (v* − v)/τ_v`, `ω̇ = (ω* − ω)/τ_ω` (`me` carries the actual
    /// `v`, `ω`), so the point `L` ahead has relative degree two:
    ///
    /// ```text
    /// p̈ = R(θ) (v̇ − L ω², L ω̇ + v ω) = f + R(θ) diag(1/τ_v, 1/τ_ω) x
    /// f = R(θ) (−v/τ_v − L ω², v ω − L ω/τ_ω)
    /// ```
    ///
    /// and the exponential barrier `ḧ + (γ + p) ḣ + γ p h ≥ 0` of the torque
    /// filter applies ([`SafetyFilter::second_order_barriers`]), with the
    /// speed envelope ([`Envelope`]: no reverse, the base's speeds) as soft
    /// rows, and as hard rows the base's speed limits on the command and its
    /// acceleration limits on the lags' response (`|v* − v| ≤ τ_v a_max`,
    /// `|ω* − ω| ≤ τ_ω α_max`: within them the base responds as the lag says,
    /// the joint scaling never acts). With the command held for a period the
    /// lags are taken as seen over it ([`SafetyFilter::held_lag`]: a lag-free
    /// axis lags by the period).
    fn lagged(&mut self, call: Call<'_>) -> Filtered<VelocityCommand> {
        let Call {
            t,
            me,
            l,
            nominal,
            base,
            neighbours,
            obstacles,
        } = call;
        let (tv, tw) = (self.held_lag(base.tau_v()), self.held_lag(base.tau_omega()));
        let own = Own::ahead(me, l, 0.0);
        let (v, w) = (me.v, me.omega);
        let along = -v / tv - l * w * w;
        let across = v * w - l * w / tw;
        let f = [
            along * own.cos - across * own.sin,
            along * own.sin + across * own.cos,
        ];
        let limited = self.reversing(base.limit(nominal).0);
        let x0 = [limited.v, l * limited.omega];
        self.rows.clear();
        let min_distance =
            self.second_order_barriers(&own, neighbours, obstacles, f, [1.0 / tv, 1.0 / tw], false);
        let barriers = self.rows.len();
        Envelope::lagged(base).push_rows(
            &mut self.rows,
            [1.0 / tv, 1.0 / (l * tw)],
            [v / tv, w / tw],
            v,
            w,
        );
        let soft_end = self.rows.len();
        // The hard rows: the speed limits on the command, the acceleration
        // limits on the lags' response.
        push_box(&mut self.rows, [base.v_max(), l * base.omega_max()]);
        self.push_reverse();
        let reach = |tau: f64, max: f64| if max.is_finite() { tau * max } else { max };
        push_band(
            &mut self.rows,
            [v, l * w],
            [
                reach(base.tau_v(), base.a_max()),
                l * reach(base.tau_omega(), base.alpha_max()),
            ],
        );
        let decision = self.decide(t, x0, barriers, [0.0, 0.0], Speed::State(me, l));
        let of = |x: [f64; 2]| VelocityCommand {
            v: x[0],
            omega: x[1] / l,
        };
        // No command satisfies every row: the barriers alone within the
        // hard rows, else the least violation within them (a base without
        // limits: within EMERGENCY_ACCEL of its speeds); zero if even that
        // fails.
        let braked = || {
            let fallback = [[v, l * w], [tv * EMERGENCY_ACCEL, tw * EMERGENCY_ACCEL]];
            self.emergency(barriers, obstacles.len(), soft_end, x0, fallback)
                .map_or(VelocityCommand::default(), of)
        };
        Filtered::decided(decision, nominal, limited, min_distance, of, braked)
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use super::*;
    use crate::model::base::VelocityBaseSpec;
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

    /// A non-finite nominal or state (a run blowing up) is passed on as it
    /// is, for the divergence guard to report: no panic, no QP on it, on an
    /// ideal base and on a lagged one.
    #[test]
    fn non_finite_input_passes_through_unchanged() {
        use crate::safety::strategies::assert_passed;
        let l = 0.05;
        let n = Neighbour::of_state(
            &State::at_rest(0.6, 0.0, std::f64::consts::PI),
            l,
            None,
            true,
        );
        let rest = State::at_rest(0.0, 0.0, 0.0);
        let numbers = |c: VelocityCommand| [c.v, c.omega];
        for base in [ideal(), VelocityBase::TURTLEBOT4] {
            for bad in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
                let nominals = [
                    VelocityCommand { v: bad, omega: 0.0 },
                    VelocityCommand { v: 0.2, omega: bad },
                ];
                for nominal in nominals {
                    let out = SafetyFilter::new(config()).velocity(
                        0.0,
                        &rest,
                        l,
                        nominal,
                        &base,
                        &[n],
                        &[],
                    );
                    assert_passed(&out, nominal, numbers);
                }
                let mut me = rest;
                me.v = bad;
                let nominal = VelocityCommand { v: 0.5, omega: 0.0 };
                let out =
                    SafetyFilter::new(config()).velocity(0.0, &me, l, nominal, &base, &[n], &[]);
                assert_passed(&out, nominal, numbers);
            }
        }
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

            /// Under a reverse cap (a Create 3's backup budget), on a base
            /// without lag and on a lagged one, whatever the scene: the
            /// command never backs up faster than the cap — so a backup
            /// budget applied after the filter ([`crate::model::base::Backup`])
            /// has nothing left to cut, and the command the filter
            /// certified is the one the base carries out — and a filtered
            /// command still satisfies every row.
            #[test]
            fn a_reverse_cap_is_kept(
                Scene { me, ns, config } in scene(),
                v in -0.8..0.8f64,
                omega in -3.0..3.0f64,
                cap in prop_oneof![Just(0.0), 0.0..0.3f64],
                lagged in any::<bool>(),
            ) {
                let base = if lagged { VelocityBase::TURTLEBOT4 } else { ideal() };
                let mut f = SafetyFilter::new(config);
                f.set_reverse_cap(cap);
                let nominal = VelocityCommand { v, omega };
                let out = f.velocity(0.0, &me, L, nominal, &base, &ns, &[]);
                prop_assert!(out.command.v >= -cap - TOLERANCE, "{out:?} under {cap}");
                if out.outcome == Outcome::Filtered {
                    let x = x_of(out.command, L);
                    for c in f.constraints() {
                        prop_assert!(c.slack(x) >= -TOLERANCE, "{c:?} at {x:?}");
                    }
                }
                if out.outcome == Outcome::Nominal {
                    prop_assert_eq!(out.command.v, base.limit(nominal).0.v.max(-cap));
                }
            }
        }
    }

    /// Boxed in between a neighbour that closes on its point and an obstacle
    /// just behind it (both outside the radius, at random headings, gains
    /// and speeds), a velocity base without lag never answers a command
    /// that breaks an obstacle's row: standing still keeps those, so the
    /// least violation of the neighbours' rows is sought among the commands
    /// that do (the pair's shortfall is its partner's to take over). Most
    /// of these cases are infeasible (braked): the test is not vacuous.
    #[test]
    fn boxed_in_a_robot_never_breaks_an_obstacles_row() {
        let mut rng = crate::math::rng::SplitMix64::new(20261208);
        let (l, radius) = (0.05, 0.3);
        let mut braked = 0;
        let cases = 400;
        for case in 0..cases {
            let gain = rng.uniform(0.2, 5.0);
            let config = SafetyConfig::new(radius, gain, 2.0).unwrap();
            let me = State {
                theta: rng.uniform(-3.2, 3.2),
                v: rng.uniform(0.0, 0.5),
                omega: rng.uniform(-2.0, 2.0),
                ..State::at_rest(0.0, 0.0, 0.0)
            };
            let p = crate::safety::point(&me, l);
            // The neighbour's point just outside the radius in direction
            // `a`, coming straight at this robot's point.
            let a = rng.uniform(-3.2, 3.2);
            let dist = radius + rng.uniform(1e-4, 0.03);
            let q = [p[0] + dist * a.cos(), p[1] + dist * a.sin()];
            let heading = a + std::f64::consts::PI;
            let other = State {
                x: q[0] - l * heading.cos(),
                y: q[1] - l * heading.sin(),
                theta: heading,
                v: rng.uniform(0.1, 0.5),
                omega: 0.0,
            };
            let cooperative = rng.next_u64().is_multiple_of(2);
            let n = Neighbour::of_state(&other, l, None, cooperative);
            // The obstacle on the other side, its edge just beyond the radius.
            let b = a + std::f64::consts::PI + rng.uniform(-0.6, 0.6);
            let r = rng.uniform(0.05, 0.5);
            let c = radius + r + rng.uniform(1e-4, 0.03);
            let obstacle = Obstacle::new(p[0] + c * b.cos(), p[1] + c * b.sin(), r).unwrap();
            let nominal = VelocityCommand {
                v: rng.uniform(-0.5, 0.5),
                omega: rng.uniform(-4.0, 4.0),
            };
            let mut f = SafetyFilter::new(config);
            let out = f.velocity(0.0, &me, l, nominal, &ideal(), &[n], &[obstacle]);
            braked += usize::from(out.outcome == Outcome::Braked);
            let rows = f.constraints();
            // Rows: the neighbour's (in range), the obstacle's, the box.
            let row = rows[1];
            let x = [out.command.v, l * out.command.omega];
            assert!(
                row.slack(x) >= -crate::safety::TOLERANCE,
                "case {case}: {out:?} breaks the obstacle's row {row:?} by {}",
                -row.slack(x)
            );
        }
        assert!(braked > cases / 4, "only {braked} of {cases} braked");
    }
}
