//! The excitation command of `echelon fleet excite` (pure, deterministic):
//! a manoeuvre designed so that [`identify`](super::identify) can identify
//! a velocity base's lags, dead time and — when asked — its acceleration
//! limits, from a ROS 2 bag at the base's odometry rate.
//!
//! The design starts from the prior (the scenario's base) and keeps the
//! robot in a small area:
//!
//! - a rest of [`LEAD`] s first: the bag's first command holds the rest the
//!   base was in, so the dead time's first samples are known;
//! - **steps** held `max(1 s, 8 τ, 20 odometry periods)`: several lags and
//!   many odometry samples per step, so each step's exponential is seen;
//! - step sizes on four levels `1, 1/8, 1/2, 1/4` of the largest, which is
//!   at most `0.8 a_max τ_v` (`0.8 α_max τ_ω`) of the prior: the prior's
//!   limit never binds, and a base whose true limit is up to 8 times lower
//!   than the prior's still has steps its limit does not bind on (a lag is
//!   seen) next to steps it binds on (a limit is seen: the fit tells them
//!   apart, `docs/identify.md`);
//! - the steps come in pairs `(+A, +Ω)`, `(0, 0)`, `(−A, −Ω)`, `(0, 0)`: the
//!   second arc retraces the first backwards, so under an ideal base the
//!   robot is back at its start pose every four steps;
//! - with `limits` ([`ExciteDesign::limits`]), **limit probes**: reversals
//!   `(+A, +Ω) → (−A, −Ω)` at the preset's safe speeds (`0.8 v_max`,
//!   `0.8 ω_max`, at most [`V_CAP`], [`OMEGA_CAP`]), a jump of `2A` whose
//!   lag rate `2A/τ` reaches any limit below it; without it no step is
//!   steeper than the prior's limit allows;
//! - a **chirp** of both axes from `1/(4 hold)` up to the lags' corner
//!   frequency (at most 2 Hz), its rate `A 2π f` within the prior's limits;
//!   then zero.
//!
//! Everything stays within `|v| ≤ 0.8 v_max`, `|ω| ≤ 0.8 ω_max` and the caps.

use crate::base::{VelocityBase, VelocityCommand};

/// Largest linear speed of the manoeuvre, m/s.
pub const V_CAP: f64 = 0.3;
/// Largest angular speed of the manoeuvre, rad/s.
pub const OMEGA_CAP: f64 = 1.0;
/// Fraction of each limit the manoeuvre uses.
pub const MARGIN: f64 = 0.8;
/// Rest at the start, s.
pub const LEAD: f64 = 1.0;
/// The slowest odometry a design without a known rate assumes, s (10 Hz).
pub const SLOWEST_ODOMETRY: f64 = 0.1;
/// Odometry periods per step at least.
pub const PERIODS_PER_STEP: f64 = 20.0;
/// Step sizes of the successive pairs, in units of the largest.
pub const LEVELS: [f64; 4] = [1.0, 0.125, 0.5, 0.25];
/// The shapes `(v, ω)` of the successive pairs (varied signs and ratios).
const SHAPES: [(f64, f64); 3] = [(1.0, 1.0), (0.5, -1.0), (1.0, -0.5)];
/// The limit probes: each a reversal `(v, ω) → (−v, −ω)`, then a rest.
const PROBES: [(f64, f64); 2] = [(1.0, 1.0), (1.0, -1.0)];

/// What the manoeuvre is designed for besides the prior base.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ExciteDesign {
    /// The base's odometry period, s (or [`SLOWEST_ODOMETRY`] if unknown).
    pub odom_period: f64,
    /// Add limit probes (`fleet excite --limits`).
    pub limits: bool,
}

impl Default for ExciteDesign {
    fn default() -> ExciteDesign {
        ExciteDesign {
            odom_period: SLOWEST_ODOMETRY,
            limits: false,
        }
    }
}

/// The excitation command as a function of time (module docs).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ExciteSignal {
    /// Largest step (and chirp amplitude) of `v`, m/s.
    pub v_amp: f64,
    /// Largest step (and chirp amplitude) of `ω`, rad/s.
    pub omega_amp: f64,
    /// The limit probes' `v` and `ω`, when asked for.
    pub probe: Option<[f64; 2]>,
    /// Duration of one step, s.
    pub hold: f64,
    /// End of the steps, s.
    pub steps_end: f64,
    /// End of the limit probes, start of the chirp, s.
    pub probes_end: f64,
    /// End of the chirp, s; zero from here to `duration`.
    pub chirp_end: f64,
    /// Chirp frequency at `probes_end`, Hz.
    pub f0: f64,
    /// Chirp frequency at `chirp_end`, Hz.
    pub f1: f64,
    /// Total duration, s.
    pub duration: f64,
}

impl ExciteSignal {
    /// The manoeuvre for the prior `base` lasting `duration` s (module
    /// docs): steps over the first 60 % after the rest (whole pairs), the
    /// probes if asked, the chirp until one hold before the end, zero after.
    pub fn for_base(base: &VelocityBase, duration: f64, design: ExciteDesign) -> ExciteSignal {
        // The largest jump a lag τ turns into a rate within `limit`.
        let jump = |limit: f64, tau: f64| {
            if tau > 0.0 && limit.is_finite() {
                MARGIN * limit * tau
            } else {
                f64::INFINITY
            }
        };
        let safe = [
            (MARGIN * base.v_max()).min(V_CAP),
            (MARGIN * base.omega_max()).min(OMEGA_CAP),
        ];
        let v_amp = safe[0].min(jump(base.a_max(), base.tau_v()));
        let omega_amp = safe[1].min(jump(base.alpha_max(), base.tau_omega()));
        let tau = base.tau_v().max(base.tau_omega());
        let period = if design.odom_period > 0.0 && design.odom_period.is_finite() {
            design.odom_period
        } else {
            SLOWEST_ODOMETRY
        };
        let hold = (8.0 * tau).max(1.0).max(PERIODS_PER_STEP * period);
        // Whole retraced pairs (four steps each), at least one.
        let pair = 4.0 * hold;
        let steps_end = LEAD + ((0.6 * duration - LEAD) / pair).floor().max(1.0) * pair;
        let probe = design.limits.then_some(safe);
        let probes_end = steps_end
            + if probe.is_some() {
                3.0 * hold * PROBES.len() as f64
            } else {
                0.0
            };
        // A duration too short for the steps and probes cuts them: the
        // manoeuvre ends at `duration` whatever it was doing.
        let chirp_end = (duration - hold).max(probes_end).min(duration);
        // The chirp's rate A 2π f within the acceleration limits.
        let rate_f = |limit: f64, amp: f64| {
            if limit.is_finite() && amp > 0.0 {
                MARGIN * limit / (std::f64::consts::TAU * amp)
            } else {
                f64::INFINITY
            }
        };
        let corner = if tau > 0.0 {
            1.0 / (std::f64::consts::TAU * tau)
        } else {
            2.0
        };
        let f1 = corner
            .min(2.0)
            .min(rate_f(base.a_max(), v_amp))
            .min(rate_f(base.alpha_max(), omega_amp));
        let f0 = (0.25 / hold).min(f1);
        ExciteSignal {
            v_amp,
            omega_amp,
            probe,
            hold,
            steps_end,
            probes_end,
            chirp_end,
            f0,
            f1,
            duration,
        }
    }

    /// The command at `t` s from the start (zero before [`LEAD`] and from
    /// `chirp_end` on).
    pub fn at(&self, t: f64) -> VelocityCommand {
        if !(LEAD..self.chirp_end).contains(&t) {
            return VelocityCommand::default();
        }
        let cmd = |v: f64, omega: f64| VelocityCommand { v, omega };
        if t < self.steps_end {
            let step = ((t - LEAD) / self.hold).floor() as usize;
            let pair = step / 4;
            let level = LEVELS[pair % LEVELS.len()];
            let (a, b) = SHAPES[pair % SHAPES.len()];
            let sign = match step % 4 {
                0 => 1.0,
                2 => -1.0,
                _ => 0.0,
            };
            return cmd(
                sign * level * a * self.v_amp,
                sign * level * b * self.omega_amp,
            );
        }
        if t < self.probes_end {
            let [v, w] = self.probe.unwrap_or([0.0; 2]);
            let step = ((t - self.steps_end) / self.hold).floor() as usize;
            let (a, b) = PROBES[(step / 3) % PROBES.len()];
            let sign = [1.0, -1.0, 0.0][step % 3];
            return cmd(sign * a * v, sign * b * w);
        }
        // Linear chirp: phase 2π (f0 s + (f1 − f0) s² / (2 T)).
        let s = t - self.probes_end;
        let span = self.chirp_end - self.probes_end;
        let phase =
            std::f64::consts::TAU * (self.f0 * s + (self.f1 - self.f0) * s * s / (2.0 * span));
        cmd(self.v_amp * phase.sin(), self.omega_amp * phase.sin())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::base::VelocityBaseSpec;
    use crate::identify::{self, Log, Model, simulate_axis};

    fn lab() -> VelocityBase {
        VelocityBase::new(VelocityBaseSpec {
            tau_v: 0.1,
            tau_omega: 0.1,
            v_max: 0.3,
            omega_max: 2.0,
            a_max: 1.0,
            alpha_max: 5.0,
            ..VelocityBase::IDEAL.spec()
        })
        .expect("the lab base")
    }

    fn bases() -> [VelocityBase; 3] {
        [
            lab(),
            VelocityBase::IDEAL,
            VelocityBase::new(VelocityBaseSpec {
                tau_v: 0.25,
                tau_omega: 0.4,
                v_max: 0.22,
                omega_max: 2.84,
                ..VelocityBase::IDEAL.spec()
            })
            .expect("a slow base"),
        ]
    }

    fn designs() -> [ExciteDesign; 3] {
        [
            ExciteDesign::default(),
            ExciteDesign {
                odom_period: 0.02,
                limits: false,
            },
            ExciteDesign {
                odom_period: 0.05,
                limits: true,
            },
        ]
    }

    fn grid(sig: &ExciteSignal, h: f64) -> Vec<f64> {
        let n = ((sig.duration + 2.0) / h) as usize;
        (0..n).map(|i| i as f64 * h - 1.0).collect()
    }

    #[test]
    fn the_command_stays_within_the_limits_and_its_jumps_within_the_lag_rate() {
        for b in bases() {
            for design in designs() {
                for duration in [10.0, 30.0, 90.0] {
                    let sig = ExciteSignal::for_base(&b, duration, design);
                    let bound = |limit: f64, tau: f64| {
                        if tau > 0.0 && limit.is_finite() {
                            MARGIN * limit * tau
                        } else {
                            f64::INFINITY
                        }
                    };
                    let max_jump = [
                        bound(b.a_max(), b.tau_v()),
                        bound(b.alpha_max(), b.tau_omega()),
                    ];
                    let h = 1e-3;
                    let mut last = VelocityCommand::default();
                    for t in grid(&sig, h) {
                        let c = sig.at(t);
                        assert!(
                            c.v.abs() <= MARGIN * b.v_max() + 1e-12 && c.v.abs() <= V_CAP,
                            "{b:?} {t} {c:?}"
                        );
                        assert!(
                            c.omega.abs() <= MARGIN * b.omega_max() + 1e-12
                                && c.omega.abs() <= OMEGA_CAP
                        );
                        let jump = [(c.v - last.v).abs(), (c.omega - last.omega).abs()];
                        // Only the probes asked for jump further.
                        let probing = (sig.steps_end..sig.probes_end + h).contains(&t);
                        for axis in 0..2 {
                            assert!(
                                probing || jump[axis] <= max_jump[axis] + 1e-12,
                                "{b:?} {t}: {jump:?}"
                            );
                        }
                        if t > sig.probes_end + h && t < sig.chirp_end {
                            assert!(jump[0] / h <= MARGIN * b.a_max() * 1.001, "{t}");
                            assert!(jump[1] / h <= MARGIN * b.alpha_max() * 1.001, "{t}");
                        }
                        last = c;
                    }
                    assert_eq!(sig.probe.is_some(), design.limits);
                    assert!(sig.hold >= PERIODS_PER_STEP * design.odom_period - 1e-12);
                    assert_eq!(sig.at(sig.duration), VelocityCommand::default());
                    assert_eq!(sig.at(0.5 * LEAD), VelocityCommand::default());
                    assert!(sig.v_amp > 0.0 && sig.omega_amp > 0.0);
                }
            }
        }
    }

    #[test]
    fn the_steps_span_a_factor_of_eight_so_a_lower_limit_leaves_steps_free() {
        let b = lab();
        let sig = ExciteSignal::for_base(&b, 120.0, ExciteDesign::default());
        let mut sizes: Vec<f64> = Vec::new();
        let mut t = LEAD + 0.5 * sig.hold;
        while t < sig.steps_end {
            let v = sig.at(t).v.abs();
            if v > 0.0 && !sizes.iter().any(|s| (s - v).abs() < 1e-12) {
                sizes.push(v);
            }
            t += sig.hold;
        }
        let (lo, hi) = sizes
            .iter()
            .fold((f64::INFINITY, 0.0_f64), |(l, h), s| (l.min(*s), h.max(*s)));
        assert!(hi / lo >= 8.0 - 1e-9, "{sizes:?}");
        assert!(hi <= MARGIN * b.a_max() * b.tau_v() + 1e-12);
    }

    #[test]
    fn under_an_ideal_base_the_robot_stays_within_a_metre_and_comes_back() {
        for b in bases() {
            for design in designs() {
                let sig = ExciteSignal::for_base(&b, 60.0, design);
                let h = 1e-3;
                let (mut x, mut y, mut th) = (0.0_f64, 0.0_f64, 0.0_f64);
                let mut far: f64 = 0.0;
                for t in grid(&sig, h) {
                    let c = sig.at(t);
                    x += h * c.v * th.cos();
                    y += h * c.v * th.sin();
                    th += h * c.omega;
                    far = far.max(x.hypot(y));
                    // Back at the start pose after every retraced pair.
                    let pairs = (t - LEAD) / (4.0 * sig.hold);
                    if t > LEAD + 1.0 && t <= sig.steps_end && (pairs - pairs.round()).abs() < 1e-4
                    {
                        assert!(
                            x.hypot(y) < 3e-3 && th.abs() < 3e-3,
                            "{b:?} {t}: ({x}, {y}, {th})"
                        );
                    }
                }
                assert!(far <= 1.0, "{b:?}: {far} m");
                assert!(far >= 0.5 * sig.v_amp * sig.hold, "{b:?}: it moved");
            }
        }
    }

    #[test]
    fn a_lagged_base_driven_by_it_is_identified() {
        for b in [lab(), bases()[2]] {
            let sig = ExciteSignal::for_base(&b, 40.0, ExciteDesign::default());
            let t: Vec<f64> = (0..2000).map(|i| f64::from(i) * 0.02).collect();
            let cmd: Vec<VelocityCommand> = t.iter().map(|&t| sig.at(t)).collect();
            let vc: Vec<f64> = cmd.iter().map(|c| c.v).collect();
            let wc: Vec<f64> = cmd.iter().map(|c| c.omega).collect();
            let log = Log {
                source: "excite".to_owned(),
                agent: 1,
                v: simulate_axis(&t, &vc, b.tau_v(), 1.0, 0.0),
                omega: simulate_axis(&t, &wc, b.tau_omega(), 1.0, 0.0),
                t,
                cmd: Some([vc, wc]),
                ..Log::default()
            };
            let id = identify::identify(&log, Model::Velocity).unwrap_or_else(|e| panic!("{e}"));
            let tau_v = id.get("tau_v").map(|e| e.value);
            let tau_w = id.get("tau_omega").map(|e| e.value);
            assert!(
                tau_v.is_some_and(|x| (x / b.tau_v() - 1.0).abs() < 1e-3),
                "{tau_v:?}"
            );
            assert!(
                tau_w.is_some_and(|x| (x / b.tau_omega() - 1.0).abs() < 1e-3),
                "{tau_w:?}"
            );
        }
    }
}
