//! The excitation command (pure, deterministic): steps of `v` and `ω`, then
//! a chirp of both, then a stop, within the base's limits and a small area
//! (see [`super`]).

use echelon::base::{VelocityBase, VelocityCommand};

/// Largest linear speed of the manoeuvre, m/s.
pub const V_CAP: f64 = 0.3;
/// Largest angular speed of the manoeuvre, rad/s.
pub const OMEGA_CAP: f64 = 1.0;
/// Fraction of each limit the manoeuvre uses.
pub const MARGIN: f64 = 0.8;
/// Step levels `(v, ω)` over one cycle, in units of the amplitudes: arcs
/// each retraced backwards after a stop.
const CYCLE: [(f64, f64); 12] = [
    (1.0, 1.0),
    (0.0, 0.0),
    (-1.0, -1.0),
    (0.0, 0.0),
    (0.5, -1.0),
    (0.0, 0.0),
    (-0.5, 1.0),
    (0.0, 0.0),
    (1.0, -0.5),
    (0.0, 0.0),
    (-1.0, 0.5),
    (0.0, 0.0),
];

/// The excitation command as a function of time.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ExciteSignal {
    /// Step (and chirp) amplitude of `v`, m/s.
    pub v_amp: f64,
    /// Step (and chirp) amplitude of `ω`, rad/s.
    pub omega_amp: f64,
    /// Duration of one step, s.
    pub hold: f64,
    /// End of the steps, start of the chirp, s.
    pub steps_end: f64,
    /// End of the chirp, s; zero from here to `duration`.
    pub chirp_end: f64,
    /// Chirp frequency at `steps_end`, Hz.
    pub f0: f64,
    /// Chirp frequency at `chirp_end`, Hz.
    pub f1: f64,
    /// Total duration, s.
    pub duration: f64,
}

impl ExciteSignal {
    /// The manoeuvre for `base` lasting `duration` s: amplitudes and steps
    /// within its limits (module docs), steps held `max(1 s, 8 τ)`, steps
    /// over the first 60 %, a chirp from `1/(4 hold)` up to the lags'
    /// corner frequency (at most 2 Hz) until one hold before the end, zero
    /// after.
    pub fn for_base(base: &VelocityBase, duration: f64) -> ExciteSignal {
        // The largest jump a lag τ turns into a rate within `limit`.
        let jump = |limit: f64, tau: f64| {
            if tau > 0.0 && limit.is_finite() {
                MARGIN * limit * tau
            } else {
                f64::INFINITY
            }
        };
        let v_amp = (MARGIN * base.v_max())
            .min(jump(base.a_max(), base.tau_v()))
            .min(V_CAP);
        let omega_amp = (MARGIN * base.omega_max())
            .min(jump(base.alpha_max(), base.tau_omega()))
            .min(OMEGA_CAP);
        let tau = base.tau_v().max(base.tau_omega());
        let hold = (8.0 * tau).max(1.0);
        // Whole retraced pairs (four steps each).
        let steps_end = (0.6 * duration / (4.0 * hold)).floor().max(1.0) * 4.0 * hold;
        let chirp_end = (duration - hold).max(steps_end);
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
            hold,
            steps_end,
            chirp_end,
            f0,
            f1,
            duration,
        }
    }

    /// The command at `t` s from the start (zero before 0 and from
    /// `chirp_end` on).
    pub fn at(&self, t: f64) -> VelocityCommand {
        if !(0.0..self.chirp_end).contains(&t) {
            return VelocityCommand::default();
        }
        if t < self.steps_end {
            let (v, omega) = CYCLE[(t / self.hold).floor() as usize % CYCLE.len()];
            return VelocityCommand {
                v: self.v_amp * v,
                omega: self.omega_amp * omega,
            };
        }
        // Linear chirp: phase 2π (f0 s + (f1 − f0) s² / (2 T)).
        let s = t - self.steps_end;
        let span = self.chirp_end - self.steps_end;
        let phase =
            std::f64::consts::TAU * (self.f0 * s + (self.f1 - self.f0) * s * s / (2.0 * span));
        VelocityCommand {
            v: self.v_amp * phase.sin(),
            omega: self.omega_amp * phase.sin(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use echelon::base::VelocityBaseSpec;
    use echelon::identify::{self, Log, Model, simulate_axis};

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

    fn grid(sig: &ExciteSignal, h: f64) -> Vec<f64> {
        let n = ((sig.duration + 2.0) / h) as usize;
        (0..n).map(|i| i as f64 * h - 1.0).collect()
    }

    #[test]
    fn the_command_stays_within_the_limits_and_its_jumps_within_the_lag_rate() {
        for b in bases() {
            for duration in [10.0, 30.0, 90.0] {
                let sig = ExciteSignal::for_base(&b, duration);
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
                        c.v.abs() <= MARGIN * b.v_max() && c.v.abs() <= V_CAP,
                        "{b:?} {t} {c:?}"
                    );
                    assert!(c.omega.abs() <= MARGIN * b.omega_max() && c.omega.abs() <= OMEGA_CAP);
                    let jump = [(c.v - last.v).abs(), (c.omega - last.omega).abs()];
                    for axis in 0..2 {
                        assert!(jump[axis] <= max_jump[axis] + 1e-12, "{b:?} {t}: {jump:?}");
                    }
                    // In the chirp the rate obeys the acceleration limits.
                    if t > sig.steps_end + h && t < sig.chirp_end {
                        assert!(jump[0] / h <= MARGIN * b.a_max() * 1.001, "{t}");
                        assert!(jump[1] / h <= MARGIN * b.alpha_max() * 1.001, "{t}");
                    }
                    last = c;
                }
                assert_eq!(sig.at(sig.duration), VelocityCommand::default());
                assert_eq!(sig.at(-0.5), VelocityCommand::default());
                assert!(sig.v_amp > 0.0 && sig.omega_amp > 0.0);
            }
        }
    }

    #[test]
    fn under_an_ideal_base_the_robot_stays_within_a_metre_and_comes_back() {
        for b in bases() {
            let sig = ExciteSignal::for_base(&b, 60.0);
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
                let pairs = t / (4.0 * sig.hold);
                if t > 1.0 && t <= sig.steps_end && (pairs - pairs.round()).abs() < 1e-4 {
                    // (to a 1 ms sample at the step edges)
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

    #[test]
    fn a_lagged_base_driven_by_it_is_identified() {
        for b in [lab(), bases()[2]] {
            let sig = ExciteSignal::for_base(&b, 40.0);
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
