//! How far a base may back up in one go: an iRobot Create 3 refuses to
//! drive more than about 10 cm backwards without its safety override (it
//! has no cliff sensor at the back) and reports `BACKUP_LIMIT`; a law or a
//! safety filter that asks for more leaves the robot stalled mid-manoeuvre.
//! [`Backup`] keeps every command within the budget.
//!
//! **What is counted.** `reversed` is how far the robot is behind the
//! furthest point it reached along its own path: backward travel adds to
//! it, forward travel takes from it, never below 0. So "in one go" is
//! backward travel net of what the robot drove forward since, and the
//! budget is `B = reverse_limit − reversed`.
//!
//! **The rule.** With the command held for a period `Δ` and the base a
//! first-order lag `τ_v` with acceleration limit `a` ([`VelocityBase`]),
//! commanding zero from a backward speed `s` stops the robot within
//!
//! ```text
//! D(s) = s τ_v                               (s ≤ a τ_v: the lag's exponential)
//! D(s) = (s² − (a τ_v)²) / (2a) + a τ_v²     (s > a τ_v: first at −a)
//! ```
//!
//! (`D = 0` on a base without lag). The command's backward speed `w` is the
//! largest with `max(s, w) Δ + D(max(s, w)) ≤ B`, and zero when even
//! `s Δ + D(s) > B`. By induction this keeps `D(s) ≤ B` at every command,
//! so the robot never backs up more than `reverse_limit`: over a period it
//! travels at most `max(s, w) Δ` while its speed moves towards `w`
//! monotonically, so `D(s')` is at most `D(max(s, w)) ≤ B − max(s, w) Δ ≤
//! B'`, however slowly the speed changes. Only when `s Δ + D(s) > B` must
//! the robot brake at the rate `D` counts on: then, on a base whose
//! accelerations are limited jointly (path-keeping), the angular command
//! is kept within `α_max τ_ω` of the turn rate, so that turning never slows
//! the braking. A forward command is never cut.

use super::{AccelLimit, VelocityBase, VelocityCommand};
use crate::model::State;

/// A base's backward-travel budget (see the module docs).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Backup {
    limit: f64,
    reversed: f64,
    /// The backward speed allowed for the coming period
    /// ([`Backup::plan`]), and whether the robot must brake at full rate.
    cap: f64,
    tight: bool,
}

impl Backup {
    /// A budget of `limit` m (`> 0`; infinite: none), nothing reversed yet.
    pub fn new(limit: f64) -> Backup {
        Backup {
            limit,
            reversed: 0.0,
            cap: f64::INFINITY,
            tight: false,
        }
    }

    /// The limit, m.
    pub fn limit(&self) -> f64 {
        self.limit
    }

    /// How far the robot is behind the furthest point it reached, m.
    pub fn reversed(&self) -> f64 {
        self.reversed
    }

    /// The backward speed the coming period allows ([`Backup::plan`]), m/s
    /// (infinite: no limit): what a safety filter may command
    /// ([`crate::safety::SafetyFilter::set_reverse_cap`]), so that the
    /// command it certifies is the one the base will carry out.
    #[inline]
    pub fn cap(&self) -> f64 {
        self.cap
    }

    /// The robot travelled `ds` m along its heading (negative: backwards).
    #[inline]
    pub fn observe(&mut self, ds: f64) {
        if ds.is_finite() {
            self.reversed = (self.reversed - ds).max(0.0);
        }
    }

    /// `D(s)`: how far `base` rolls backwards from backward speed `s ≥ 0`
    /// when commanded zero, m.
    #[inline]
    pub fn stopping_distance(base: &VelocityBase, s: f64) -> f64 {
        let spec = base.spec();
        let (tau, a) = (spec.tau_v, spec.a_max);
        if tau <= 0.0 {
            return 0.0;
        }
        let knee = a * tau;
        if s <= knee {
            s * tau
        } else {
            (s * s - knee * knee) / (2.0 * a) + knee * tau
        }
    }

    /// The largest backward speed `w` with `w Δ + D(w) ≤ budget`.
    fn allowed(base: &VelocityBase, budget: f64, period: f64) -> f64 {
        let spec = base.spec();
        let (tau, a) = (spec.tau_v, spec.a_max);
        let w = budget / (period + tau.max(0.0));
        if tau <= 0.0 || w <= a * tau {
            return w;
        }
        // w²/(2a) + w Δ + a τ²/2 − B = 0.
        let ad = a * period;
        -ad + (ad * ad - a * a * tau * tau + 2.0 * a * budget)
            .max(0.0)
            .sqrt()
    }

    /// Plans the coming period of `period` s for a robot in `me` (its
    /// backward speed now) on `base`: the largest backward speed the
    /// module's rule allows, or zero with braking at full rate when even
    /// the speed now has no room for another period. [`Backup::apply`]
    /// then holds every command of that period to it (a controller
    /// evaluated continuously inside the period, as the simulator's RK4
    /// stages, keeps one plan per step).
    pub fn plan(&mut self, base: &VelocityBase, me: &State, period: f64) {
        if self.limit.is_infinite() {
            return;
        }
        let budget = (self.limit - self.reversed).max(0.0);
        let s = (-me.v).max(0.0);
        let period = period.max(0.0);
        self.tight = s * period + Backup::stopping_distance(base, s) > budget;
        self.cap = match self.tight {
            true => 0.0,
            false => Backup::allowed(base, budget, period),
        };
    }

    /// `cmd` for a robot in `me` (its turn rate now) on `base` within the
    /// period's plan ([`Backup::plan`]), and whether it was changed.
    pub fn apply(
        &self,
        base: &VelocityBase,
        me: &State,
        cmd: VelocityCommand,
    ) -> (VelocityCommand, bool) {
        if self.limit.is_infinite() {
            return (cmd, false);
        }
        if cmd.v >= 0.0 {
            return match self.tight && me.v < 0.0 {
                true => (self.braking(base, me, cmd), true),
                false => (cmd, false),
            };
        }
        if cmd.v >= -self.cap {
            return (cmd, false);
        }
        (
            self.braking(
                base,
                me,
                VelocityCommand {
                    v: -self.cap,
                    ..cmd
                },
            ),
            true,
        )
    }

    /// `cmd` with its turn kept within `α_max τ_ω` of the turn rate now on
    /// a base whose accelerations are limited jointly, so that turning
    /// never slows the linear braking (the joint limit scales both).
    fn braking(&self, base: &VelocityBase, me: &State, cmd: VelocityCommand) -> VelocityCommand {
        let spec = base.spec();
        match spec.accel {
            AccelLimit::Joint if spec.tau_omega > 0.0 && spec.alpha_max.is_finite() => {
                let reach = spec.alpha_max * spec.tau_omega;
                VelocityCommand {
                    omega: cmd.omega.clamp(me.omega - reach, me.omega + reach),
                    ..cmd
                }
            }
            _ => cmd,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::base::VelocityBaseSpec;
    use proptest::prelude::*;

    fn base(tau_v: f64, a_max: f64, tau_omega: f64, alpha_max: f64, joint: bool) -> VelocityBase {
        VelocityBase::new(VelocityBaseSpec {
            tau_v,
            tau_omega,
            v_max: 0.5,
            omega_max: 2.0,
            a_max,
            alpha_max,
            accel: if joint {
                AccelLimit::Joint
            } else {
                AccelLimit::PerAxis
            },
        })
        .expect("a valid base")
    }

    /// `D(s)` is the distance the base model itself rolls when commanded
    /// zero (RK4 to rest), within the integration's error.
    #[test]
    fn stopping_distance_is_the_models() {
        for (tau, a) in [(0.1, f64::INFINITY), (0.2, 0.4), (0.05, 20.0), (0.3, 0.9)] {
            let b = base(tau, a, 0.1, f64::INFINITY, false);
            for s in [0.01, 0.1, 0.3, 0.5] {
                let mut st = State {
                    v: -s,
                    ..State::default()
                };
                let mut rolled = 0.0;
                let dt = 1e-4;
                for _ in 0..200_000 {
                    let next = b.rk4_step(&st, VelocityCommand::default(), dt);
                    rolled += st.x - next.x;
                    st = next;
                    if st.v.abs() < 1e-12 {
                        break;
                    }
                }
                let d = Backup::stopping_distance(&b, s);
                assert!(
                    (rolled - d).abs() < 1e-5 * (1.0 + d),
                    "τ {tau} a {a} s {s}: {rolled} vs {d}"
                );
            }
        }
    }

    proptest! {
        /// A law that only wants to back up (any speed, any turn, changing
        /// at random), on any base, at any control period: the robot never
        /// gets more than the limit behind its furthest point.
        #[test]
        fn never_more_than_the_limit_behind(
            // Lags of 0 (ideal) or at least 10 integration steps: RK4 on a
            // lag shorter than its step is not the plant (it is unstable
            // beyond dt/τ ≈ 2.8; the simulator wants dt ≤ τ).
            tau_v in prop_oneof![Just(0.0), 0.01f64..0.4],
            a_max in prop_oneof![Just(f64::INFINITY), 0.2f64..5.0],
            tau_omega in prop_oneof![Just(0.0), 0.01f64..0.3],
            alpha_max in prop_oneof![Just(f64::INFINITY), 0.5f64..10.0],
            joint in any::<bool>(),
            limit in 0.02f64..0.5,
            period in 0.005f64..0.2,
            wants in proptest::collection::vec((-0.5f64..0.05, -2.0f64..2.0), 1..20),
        ) {
            let a_max = if tau_v == 0.0 { f64::INFINITY } else { a_max };
            let alpha_max = if tau_omega == 0.0 { f64::INFINITY } else { alpha_max };
            let b = base(tau_v, a_max, tau_omega, alpha_max, joint);
            let mut backup = Backup::new(limit);
            let mut st = State::default();
            let mut worst = 0.0f64;
            let dt = 1e-3;
            let steps = ((period / dt).round() as usize).max(1);
            for k in 0..400 {
                let (v, w) = wants[k % wants.len()];
                backup.plan(&b, &st, steps as f64 * dt);
                let (cmd, _) = backup.apply(&b, &st, VelocityCommand { v, omega: w });
                let (cmd, _) = b.limit(cmd);
                for _ in 0..steps {
                    let next = b.rk4_step(&st, cmd, dt);
                    let (sin, cos) = st.theta.sin_cos();
                    let ds = (next.x - st.x) * cos + (next.y - st.y) * sin;
                    backup.observe(ds);
                    st = next;
                    worst = worst.max(backup.reversed());
                }
            }
            prop_assert!(worst <= limit * (1.0 + 1e-3) + 1e-6, "backed up {worst} > {limit}");
        }
    }
}
