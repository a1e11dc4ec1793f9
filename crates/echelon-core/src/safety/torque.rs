//! The filter for torque-driven robots (eq. 3): exponential barriers of
//! relative degree two, the speed envelope ([`Envelope`]) and the wheel
//! torque limit.

use super::filter::{EMERGENCY_ACCEL, Envelope, Filtered, Own, SafetyFilter, Speed};
use super::neighbour::{Neighbour, Obstacle};
use super::qp::{Constraint, push_band, solve_relaxed, solve_split};
use crate::model::{Input, RobotParams, State};

/// How the torque filter holds its nominal to the envelope.
impl Envelope {
    /// The nominal `x0 = (u1/m, L u2/J)` held to the envelope's top speed
    /// once the robot is at it (`v ≥ v_max`: the row `v̇ ≤ κ (v_max − v)`,
    /// one coordinate, so this is the projection onto it), not to its reverse bound (a law that brakes at low speed keeps
    /// its braking) nor to its turn rate (a law's sharp turn at the start is
    /// its own; the `obstacle-slalom` golden moved when it was held).
    fn clip(&self, robot: &RobotParams, v: f64, x0: [f64; 2]) -> [f64; 2] {
        if v < self.v_max {
            // Below the top speed the law accelerates as it likes (holding
            // it to the row from rest moved the `obstacle-slalom` golden).
            return x0;
        }
        let dv = robot.linear_friction() * v / robot.mass();
        // v̇ = x₁ − η v/m ≤ κ (v_max − v)
        [x0[0].min(self.rate * (self.v_max - v) + dv), x0[1]]
    }

    /// The nominal inputs as the filter takes them: held to the top speed
    /// ([`Envelope::clip`]), then to the wheel torques with
    /// the turn kept ([`RobotParams::limit`]); bit for bit the law's when
    /// neither acts.
    fn hold(&self, robot: &RobotParams, l: f64, me: &State, nominal: Input) -> Input {
        let (m, j) = (robot.mass(), robot.inertia());
        let x_law = [nominal.u1 / m, l * nominal.u2 / j];
        let x_env = self.clip(robot, me.v, x_law);
        let held = if x_env == x_law {
            nominal
        } else {
            Input {
                u1: m * x_env[0],
                u2: j * x_env[1] / l,
            }
        };
        robot.limit(held).0
    }
}

impl SafetyFilter {
    /// Filters a torque-driven robot's inputs `nominal` (eq. 3) at time `t`:
    /// `ḧ + (γ + p) ḣ + γ p h ≥ 0` for every neighbour in range and every obstacle,
    /// and the wheel torque limit if `robot` has one.
    #[allow(clippy::too_many_arguments)]
    pub fn torque(
        &mut self,
        t: f64,
        me: &State,
        l: f64,
        robot: &RobotParams,
        nominal: Input,
        neighbours: &[Neighbour],
        obstacles: &[Obstacle],
    ) -> Filtered<Input> {
        if !(me.is_finite() && nominal.u1.is_finite() && nominal.u2.is_finite()) {
            // Diverged: the non-finite value goes on for the divergence
            // guard to report (`crate::sim::guard`), no QP on it.
            return Filtered::passed(nominal);
        }
        let own = Own::ahead(me, l, 0.0);
        let (m, j) = (robot.mass(), robot.inertia());
        let (eta, psi) = (robot.linear_friction(), robot.angular_friction());
        let (v, w) = (me.v, me.omega);
        // p̈_i = f + R(θ) x with x = (u1/m, L u2/J).
        let along = -eta * v / m - l * w * w;
        let across = v * w - l * psi * w / j;
        let f = [
            along * own.cos - across * own.sin,
            along * own.sin + across * own.cos,
        ];
        // The nominal held to the envelope's top speed, then
        // to the wheel torques with its turn kept: the law may not run a
        // robot at 7 m/s among others (a crossing that fell metres behind
        // did, and the barriers, rows of a QP it never reached, could not
        // stop it in time).
        let limited = Envelope::DEFAULT.hold(robot, l, me, nominal);
        let x0 = [limited.u1 / m, l * limited.u2 / j];
        self.rows.clear();
        let min_distance =
            self.second_order_barriers(&own, neighbours, obstacles, f, [1.0, 1.0], true);
        // The speed envelope ([`Envelope`]) bounds what the QP may answer; a
        // nominal that satisfies every barrier passes as it is.
        let barriers = self.rows.len();
        let drag = [eta * v / m, psi * w / j];
        Envelope::DEFAULT.push_rows(&mut self.rows, [1.0, 1.0 / l], drag, v, w);
        // Barriers and the envelope may give way in an emergency; the wheel
        // torque rows below may not.
        let soft_end = self.rows.len();
        if let Some(limit) = robot.torque_limit() {
            // τ_r,l = r (u1 ± u2/l_w)/2, |τ| ≤ limit:
            // |m x₁ ± J x₂ /(L l_w)| ≤ 2 limit / r.
            let bound = 2.0 * limit / robot.wheel_radius();
            let k = j / (l * robot.half_wheelbase());
            for s in [1.0, -1.0] {
                for sign in [1.0, -1.0] {
                    self.rows.push(Constraint {
                        a: [-sign * m, -sign * s * k],
                        b: -bound,
                    });
                }
            }
        }
        let decision = self.decide(t, x0, barriers, f, Speed::State(me, l));
        let of = move |x: [f64; 2]| Input {
            u1: m * x[0],
            u2: j * x[1] / l,
        };
        // No command satisfies every row: the emergency action
        // ([`SafetyFilter::emergency`]), friction's brake only if even that
        // fails.
        let braked = || {
            let brake = robot.brake(me);
            let xb = [brake.u1 / m, l * brake.u2 / j];
            let bound = [0, 1].map(|k| EMERGENCY_ACCEL.max(x0[k].abs()).max(xb[k].abs()));
            self.emergency(barriers, obstacles.len(), soft_end, x0, [[0.0; 2], bound])
                .map_or(brake, of)
        };
        let out = Filtered::decided(decision, nominal, limited, min_distance, of, braked);
        self.last = out.command;
        out
    }

    /// `(v̇, ω̇)` of its robot (`robot`, at `me`) under the torques this
    /// filter answered last (zero before its first call), the command it
    /// carries out until the next call: what a neighbour's filter takes as
    /// this robot's acceleration ([`Neighbour::of_state`]'s `dv`,
    /// [`Neighbour::sharing`]) to see whether it took its half of their
    /// barrier.
    pub fn last_acceleration(&self, me: &State, robot: &RobotParams) -> [f64; 2] {
        let d = robot.derivative(me, self.last);
        [d.v, d.omega]
    }
}

impl SafetyFilter {
    /// The emergency action when no command satisfies every row (barriers
    /// `..barriers`, the last `obstacles` of them an obstacle's each, the
    /// envelope `..soft_end`, the hard rows after): the barriers alone, the
    /// envelope given up, within the hard rows; else the command that breaks
    /// the neighbours' rows and the envelope least (one shared slack) within
    /// the hard rows and clear of every obstacle (which cannot move out of
    /// the way, as a neighbour takes over its partner's shortfall); else the
    /// one that breaks every barrier and the envelope least within the hard
    /// rows. The hard rows are the robot's own limits (wheel
    /// torques; a velocity base's speeds and accelerations), or for a robot
    /// without any the band `|x_k − centre_k| ≤ bound_k` of `fallback =
    /// [centre, bound]` (pushed here; a torque-driven robot's is `|x_k| ≤
    /// max(EMERGENCY_ACCEL, |x0_k|, |brake_k|)`): a bounded action that still
    /// takes the robot's share of every pair. A bare friction brake did not:
    /// a robot that braked at 50 m/s² left the one behind it, which counts on
    /// its half of their pair, to run into it (a randomized crossing came
    /// 255 mm inside a 0.35 m radius).
    pub(super) fn emergency(
        &mut self,
        barriers: usize,
        obstacles: usize,
        soft_end: usize,
        x0: [f64; 2],
        [centre, bound]: [[f64; 2]; 2],
    ) -> Option<[f64; 2]> {
        if self.rows.len() == soft_end {
            push_band(&mut self.rows, centre, bound);
        }
        if let Some(x) = solve_split(&self.rows[..barriers], &self.rows[soft_end..], x0) {
            return Some(x);
        }
        if obstacles > 0 {
            // The obstacles' rows moved among the hard ones for the solve
            // (neighbours, envelope | obstacles, hard), then back.
            let first = barriers - obstacles;
            self.rows[first..soft_end].rotate_left(obstacles);
            let clear = solve_relaxed(&self.rows, soft_end - obstacles, x0);
            self.rows[first..soft_end].rotate_right(obstacles);
            if clear.is_some() {
                return clear;
            }
        }
        solve_relaxed(&self.rows, soft_end, x0)
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use super::*;
    use crate::safety::Outcome;

    /// A non-finite nominal or state (a run blowing up) is passed on as it
    /// is, for the divergence guard to report: no panic, no QP on it.
    #[test]
    fn non_finite_input_passes_through_unchanged() {
        use crate::safety::SafetyConfig;
        use crate::safety::strategies::assert_passed;
        let l = 0.05;
        let robot = RobotParams::AGENT1;
        let other = State::at_rest(0.6, 0.0, std::f64::consts::PI);
        let n = Neighbour::of_state(&other, l, None, true);
        let config = SafetyConfig::new(0.3, 1.0, 2.0).unwrap();
        let rest = State::at_rest(0.0, 0.0, 0.0);
        let numbers = |u: Input| [u.u1, u.u2];
        for bad in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
            for nominal in [Input { u1: bad, u2: 0.0 }, Input { u1: 1.0, u2: bad }] {
                let out =
                    SafetyFilter::new(config).torque(0.0, &rest, l, &robot, nominal, &[n], &[]);
                assert_passed(&out, nominal, numbers);
            }
            let mut me = rest;
            me.omega = bad;
            let nominal = Input { u1: 5.0, u2: 0.0 };
            let out = SafetyFilter::new(config).torque(0.0, &me, l, &robot, nominal, &[n], &[]);
            assert_passed(&out, nominal, numbers);
        }
    }

    mod properties {
        use super::*;
        use crate::safety::TOLERANCE;
        use crate::safety::strategies::{L, Scene, scene};
        use proptest::prelude::*;

        /// `x` of the QP for a torque command.
        fn x_of(robot: &RobotParams, u: Input) -> [f64; 2] {
            [u.u1 / robot.mass(), L * u.u2 / robot.inertia()]
        }

        proptest! {
            /// The same for the torque filter's exponential barriers and the
            /// wheel torque limit.
            #[test]
            fn torque_filter_satisfies_its_constraints(
                Scene { me, ns, config } in scene(),
                u1 in -60.0..60.0f64,
                u2 in -10.0..10.0f64,
            ) {
                let robot = RobotParams::AGENT1.with_torque_limit(Some(3.0)).unwrap();
                let mut f = SafetyFilter::new(config);
                let nominal = Input { u1, u2 };
                let out = f.torque(0.0, &me, L, &robot, nominal, &ns, &[]);
                let rows = f.constraints().to_vec();
                let x_of = |u: Input| x_of(&robot, u);
                // Barriers, then the speed envelope (4 rows), then the torque limit (4).
                let barriers = rows.len() - 8;
                // The nominal is first held to the envelope's top speed and
                // then limited with its turn kept.
                let limited = Envelope::DEFAULT.hold(&robot, L, &me, nominal);
                // (the states here are below the top speed: untouched)
                prop_assert_eq!(limited, robot.limit(nominal).0);
                let nominal_ok = rows[..barriers].iter().all(|c| c.slack(x_of(limited)) >= 0.0);
                match out.outcome {
                    Outcome::Nominal => {
                        prop_assert!(nominal_ok);
                        prop_assert_eq!(out.command, limited);
                    }
                    Outcome::Filtered => {
                        let x = x_of(out.command);
                        for c in &rows {
                            // relative to the row's bound (the torque rows are in N)
                            let scale = 1.0 + c.b.abs();
                            prop_assert!(c.slack(x) >= -TOLERANCE * scale, "{c:?} at {x:?}");
                        }
                    }
                    Outcome::Braked => {
                        // The least-violating command within the wheel
                        // torque limits (the last four rows), else
                        // friction's brake.
                        let brake = Input { u1: -robot.linear_friction() * me.v, u2: -robot.angular_friction() * me.omega };
                        if out.command != brake {
                            let x = x_of(out.command);
                            for c in &rows[rows.len() - 4..] {
                                let scale = 1.0 + c.b.abs();
                                prop_assert!(c.slack(x) >= -TOLERANCE * scale, "{c:?} at {x:?}");
                            }
                        }
                    }
                }
                if nominal_ok {
                    prop_assert_eq!(out.outcome, Outcome::Nominal);
                }
            }

            /// Without wheel-torque limits the emergency action is bounded:
            /// within the box `|x_k| ≤ max(EMERGENCY_ACCEL, |x0_k|, |brake_k|)`
            /// (the last four rows, pushed for it), and it keeps every
            /// barrier whenever some command in the box does (the envelope
            /// given up), which a friction brake did not.
            #[test]
            fn torque_emergency_without_limits_is_bounded_and_keeps_the_barriers(
                Scene { me, ns, config } in scene(),
                u1 in -60.0..60.0f64,
                u2 in -10.0..10.0f64,
            ) {
                let robot = RobotParams::AGENT1;
                let mut f = SafetyFilter::new(config);
                let out = f.torque(0.0, &me, L, &robot, Input { u1, u2 }, &ns, &[]);
                let x_of = |u: Input| x_of(&robot, u);
                prop_assert!(out.command.u1.is_finite() && out.command.u2.is_finite());
                if out.outcome == Outcome::Braked {
                    let rows = f.constraints().to_vec();
                    // barriers, the envelope (4), the box (4)
                    let barriers = rows.len() - 8;
                    let x = x_of(out.command);
                    for c in &rows[rows.len() - 4..] {
                        prop_assert!(c.a[0].abs() + c.a[1].abs() == 1.0);
                        prop_assert!(c.slack(x) >= -TOLERANCE * (1.0 + c.b.abs()), "{c:?} at {x:?}");
                    }
                    let bound = -rows[rows.len() - 4].b;
                    prop_assert!(bound >= EMERGENCY_ACCEL);
                    // Some corner or the centre of the box keeps every
                    // barrier: so must the answer.
                    let b2 = -rows[rows.len() - 2].b;
                    let feasible = [[0.0, 0.0], [bound, b2], [bound, -b2], [-bound, b2], [-bound, -b2]]
                        .into_iter()
                        .any(|z| rows[..barriers].iter().all(|c| c.slack(z) >= 0.0));
                    if feasible {
                        for c in &rows[..barriers] {
                            prop_assert!(c.slack(x) >= -TOLERANCE * (1.0 + c.b.abs()), "{c:?} at {x:?}");
                        }
                    }
                }
            }
        }
    }
}
