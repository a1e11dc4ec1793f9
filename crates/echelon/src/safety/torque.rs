//! The filter for torque-driven robots (eq. 3): exponential barriers of
//! relative degree two, the speed envelope ([`Envelope`]) and the wheel
//! torque limit.

use super::filter::{Filtered, Own, SafetyFilter};
use super::neighbour::{Neighbour, Obstacle};
use super::qp::{Constraint, push_box, solve_relaxed, solve_split};
use crate::model::{Input, RobotParams, State};

/// `p`, 1/s: the inner pole of the torque barrier, `ψ̇₁ + p ψ₁ ≥ 0` with
/// `ψ₁ = ḣ + γ h` (`p = max(γ, INNER_RATE)`). With both poles at `−γ` (the
/// filter before issue 20) `ψ₁` could fall no faster than `γ ψ₁`, and since
/// `ḧ` carries `2 dᵀp̈`, which grows with the distance `d`, a robot moving
/// away from a neighbour metres off was forbidden to brake (friction alone
/// decelerates Table I's robots at `η v/m ≈ 6 m/s²` at 1 m/s): the filter
/// kept it driving away, the law's braking refused. `ψ₁ ≥ 0` still keeps
/// `h ≥ 0`; the inner loop, on the robot's acceleration, is just allowed to
/// be faster than the outer one.
pub const INNER_RATE: f64 = 5.0;

/// The smallest half-width, m/s², of the acceleration box in which a
/// torque-driven robot without wheel-torque limits takes its emergency
/// action (the box also holds the nominal and friction's brake).
pub const EMERGENCY_ACCEL: f64 = 20.0;

/// The speed envelope a torque-driven robot's filtered command keeps it in:
/// `−v_reverse ≤ v ≤ v_max`, `|ω| ≤ omega_max`, each as a first-order barrier
/// `ḣ ≥ −κ h` on `(u1, u2)` (`v̇ = (u1 − η v)/m`, `ω̇ = (u2 − ψ ω)/J`, eq. 3),
/// rows of the QP like the torque limit (a nominal command that satisfies
/// every barrier is not held to them).
///
/// Why (issue 20): the filter steers the point `L` ahead, whose acceleration
/// `(u1/m, L u2/J)` the QP changes as little as possible. The heading is that
/// output's internal (zero) dynamics: holding the point's lateral
/// acceleration needs `ω̇ ≈ −(v/L) ω`, unstable at rate `|v|/L` whenever
/// `v < 0` (20/s per m/s at `L = 0.05 m`), and a lateral correction of the
/// point costs the QP `L` times less than the angular acceleration it
/// demands. Unbounded, a filter that pushed a robot backwards made it spin
/// up (12 rad/s in 3 s) and the run diverge (‖e‖ ≈ 1e213 m). The envelope
/// bounds the state the filter may create, and with no reverse (the default)
/// the heading stays on the stable side of its zero dynamics: the filter may
/// slow a robot to a stop, never drive it backwards. When the envelope and
/// the barriers conflict the QP is infeasible and the robot brakes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Envelope {
    /// Largest forward speed, m/s.
    pub v_max: f64,
    /// Largest reverse speed, m/s (`v ≥ −v_reverse`).
    pub v_reverse: f64,
    /// Largest turn rate, rad/s.
    pub omega_max: f64,
    /// `κ`, 1/s: how fast the state is brought back inside.
    pub rate: f64,
}

impl Envelope {
    /// The default envelope: 1.5 m/s forward, no reverse, 4 rad/s, κ = 5/s.
    pub const DEFAULT: Envelope = Envelope {
        v_max: 1.5,
        v_reverse: 0.0,
        omega_max: 4.0,
        rate: 5.0,
    };

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

    /// The four rows in the QP's variables `x = (u1/m, L u2/J)` at speeds
    /// `(v, w)`: `v̇ = x₁ − η v/m`, `ω̇ = x₂/L − ψ ω/J`.
    fn push_rows(&self, rows: &mut Vec<Constraint>, robot: &RobotParams, l: f64, v: f64, w: f64) {
        let k = self.rate;
        let dv = robot.linear_friction() * v / robot.mass();
        let dw = robot.angular_friction() * w / robot.inertia();
        // v_max − v ≥ 0:      −v̇ ≥ −κ (v_max − v)
        rows.push(Constraint {
            a: [-1.0, 0.0],
            b: -k * (self.v_max - v) - dv,
        });
        // v + v_reverse ≥ 0:   v̇ ≥ −κ (v + v_reverse)
        rows.push(Constraint {
            a: [1.0, 0.0],
            b: -k * (v + self.v_reverse) + dv,
        });
        // omega_max ∓ ω ≥ 0
        rows.push(Constraint {
            a: [0.0, -1.0 / l],
            b: -k * (self.omega_max - w) - dw,
        });
        rows.push(Constraint {
            a: [0.0, 1.0 / l],
            b: -k * (self.omega_max + w) + dw,
        });
    }
}

impl SafetyFilter {
    /// Filters a torque-driven robot's inputs `nominal` (eq. 3) at time `t`:
    /// `ḧ + 2γ ḣ + γ² h ≥ 0` for every neighbour in range and every obstacle,
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
        let gamma = self.config.gain;
        self.rows.clear();
        let min_distance = self.barriers(&own, neighbours, obstacles, |d, h, n| {
            let a = own.row(d);
            let (dpj, ddpj) = n.map_or(([0.0; 2], [0.0; 2]), |n| (n.dp, n.ddp));
            let rel = [own.dp[0] - dpj[0], own.dp[1] - dpj[1]];
            let dh = 2.0 * (d[0] * rel[0] + d[1] * rel[1]);
            // Everything in ḧ + (γ + p) ḣ + γ p h that u does not move
            // (ψ₁ = ḣ + γ h, ψ̇₁ + p ψ₁ ≥ 0).
            let p = INNER_RATE.max(gamma);
            let drift =
                2.0 * (rel[0] * rel[0] + rel[1] * rel[1]) + (gamma + p) * dh + gamma * p * h;
            let df = 2.0 * (d[0] * f[0] + d[1] * f[1]);
            let b = match n {
                Some(n) if n.cooperative => -df - 0.5 * drift,
                _ => -df + 2.0 * (d[0] * ddpj[0] + d[1] * ddpj[1]) - drift,
            };
            Constraint { a, b }
        });
        // The speed envelope ([`Envelope`]) bounds what the QP may answer; a
        // nominal that satisfies every barrier passes as it is.
        let barriers = self.rows.len();
        Envelope::DEFAULT.push_rows(&mut self.rows, robot, l, v, w);
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
        let decision = self.decide(t, x0, barriers, f);
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
            self.emergency(barriers, soft_end, x0, xb).map_or(brake, of)
        };
        Filtered::decided(decision, nominal, limited, min_distance, of, braked)
    }
}

impl SafetyFilter {
    /// The emergency action when no command satisfies every row (barriers
    /// `..barriers`, the envelope `..soft_end`, the wheel-torque rows after):
    /// the barriers alone, the envelope given up, within the hard rows; else
    /// the command that breaks the barriers and the envelope least (one
    /// shared slack) within them. The hard rows are the wheel-torque limits,
    /// or for a robot without them the box `|x_k| ≤ max(EMERGENCY_ACCEL,
    /// |x0_k|, |brake_k|)` (pushed here): a bounded action that still takes
    /// the robot's share of every pair. A bare friction brake did not: a
    /// robot that braked at 50 m/s² left the one behind it, which counts on
    /// its half of their pair, to run into it (a randomized crossing came
    /// 255 mm inside a 0.35 m radius).
    fn emergency(
        &mut self,
        barriers: usize,
        soft_end: usize,
        x0: [f64; 2],
        brake: [f64; 2],
    ) -> Option<[f64; 2]> {
        if self.rows.len() == soft_end {
            let bound = [0, 1].map(|k| EMERGENCY_ACCEL.max(x0[k].abs()).max(brake[k].abs()));
            push_box(&mut self.rows, bound);
        }
        solve_split(&self.rows[..barriers], &self.rows[soft_end..], x0)
            .or_else(|| solve_relaxed(&self.rows, soft_end, x0))
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use super::*;
    use crate::safety::Outcome;

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
