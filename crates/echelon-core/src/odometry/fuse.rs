//! Absolute fixes fused with odometry (paper section 6): one implementation
//! for the simulator's [`super::Odometer`] and for a fleet robot that takes
//! fixes from ROS 2 poses.
//!
//! A fix measures the pose at the instant it was *taken*; it reaches the
//! estimator later (latency). [`FixFusion::apply`] carries it to now by the
//! motion the odometry measured since (`fix ⊕ (then⁻¹ ⊕ now)`: exact when the
//! odometry's error over that interval is negligible, whatever its error
//! before), optionally gates it (a fix whose squared Mahalanobis distance
//! from the estimate is implausible is refused and counted, the estimate
//! unchanged), then either replaces the estimate by it (`reset`, the paper's
//! recalibration) or fuses it in the EKF ([`Ekf`]).

use super::Fusion;
use super::ekf::Ekf;
use crate::model::Pose;

/// The 99.9 % quantile of the chi-square distribution with 2 degrees of
/// freedom (`−2 ln 0.001`): a position fix consistent with the estimate's
/// and its own uncertainty is farther than this one time in a thousand.
pub const GATE_2DOF: f64 = 13.815_510_557_964_27;

/// The 99.9 % quantile of the chi-square distribution with 3 degrees of
/// freedom (position and heading).
pub const GATE_3DOF: f64 = 16.266_236_196_238_13;

/// A fix's uncertainty: the standard deviation of each position coordinate
/// (m) and of the heading (rad; `None`: the fix gives no heading).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FixNoise {
    /// Per position coordinate, m.
    pub position: f64,
    /// Heading, rad (`None`: no heading measured).
    pub heading: Option<f64>,
}

/// A fix refused by the gate: its squared Mahalanobis distance from the
/// estimate and the threshold it exceeded.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Gated {
    /// `νᵀ S⁻¹ ν`.
    pub distance_sq: f64,
    /// The gate's threshold.
    pub threshold: f64,
}

/// What fuses fixes into one robot's estimate: the fusion rule, the
/// estimate's covariance (when the rule is `ekf`, or a gate needs it), the
/// gate and the counts.
#[derive(Debug, Clone, PartialEq)]
pub struct FixFusion {
    fusion: Fusion,
    /// The covariance of the estimate: the EKF's own, or, for a gated
    /// `reset`, the same propagation (odometry grows it, a reset sets it to
    /// the fix's) so that the gate weighs the odometry's drift since the
    /// last fix.
    ekf: Option<Ekf>,
    /// Whether implausible fixes are refused (chi-square 99.9 %).
    gate: bool,
    applied: u64,
    gated: u64,
}

impl FixFusion {
    /// Fusion by `fusion`, the start pose known exactly; `gate`: refuse fixes
    /// farther than the chi-square 99.9 % quantile ([`GATE_2DOF`],
    /// [`GATE_3DOF`]) from the estimate.
    pub fn new(fusion: Fusion, gate: bool) -> FixFusion {
        FixFusion {
            fusion,
            ekf: (fusion == Fusion::Ekf || gate).then(Ekf::new),
            gate,
            applied: 0,
            gated: 0,
        }
    }

    /// The covariance filter, when fusing by `ekf` or gating (the odometry
    /// predicts through it).
    pub fn ekf_mut(&mut self) -> Option<&mut Ekf> {
        self.ekf.as_mut()
    }

    /// The estimate's covariance of `(x, y, θ)` when fusing by `ekf` or
    /// gating.
    pub fn covariance(&self) -> Option<[[f64; 3]; 3]> {
        self.ekf.as_ref().map(Ekf::covariance)
    }

    /// Fixes applied.
    pub fn applied(&self) -> u64 {
        self.applied
    }

    /// Fixes refused by the gate.
    pub fn gated(&self) -> u64 {
        self.gated
    }

    /// The fix `fix` of the pose at the instant the estimate was `then`,
    /// fused into the estimate now, `estimate`: the new estimate, or the
    /// gate's refusal (the estimate and the covariance then unchanged).
    ///
    /// Without a heading in the fix the estimate's heading is kept. The gate
    /// needs an uncertainty: with `reset` fusion and a noiseless fix nothing
    /// is gated (a stated zero noise is trusted).
    pub fn apply(
        &mut self,
        estimate: &Pose,
        then: &Pose,
        fix: &Pose,
        noise: FixNoise,
    ) -> Result<Pose, Gated> {
        let mut now = carry(fix, then, estimate);
        if noise.heading.is_none() {
            now.theta = estimate.theta;
        }
        if self.gate {
            let threshold = if noise.heading.is_some() {
                GATE_3DOF
            } else {
                GATE_2DOF
            };
            let uncertain = noise.position > 0.0 || self.fusion == Fusion::Ekf;
            let d2 = match &self.ekf {
                Some(ekf) => ekf.distance_sq(estimate, &now, noise.position, noise.heading),
                None => Ekf::new().distance_sq(estimate, &now, noise.position, noise.heading),
            };
            if uncertain && d2 > threshold {
                self.gated += 1;
                return Err(Gated {
                    distance_sq: d2,
                    threshold,
                });
            }
        }
        Ok(self.fuse(estimate, now, noise))
    }

    /// `fix`, taken at the instant the estimate was `then`, replaces the
    /// estimate now whatever the gate says (a robot relocalised after its
    /// odometry drifted beyond what the gate believes): carried to now, the
    /// covariance reset to the fix's.
    pub fn reset(&mut self, estimate: &Pose, then: &Pose, fix: &Pose, noise: FixNoise) -> Pose {
        let mut now = carry(fix, then, estimate);
        if noise.heading.is_none() {
            now.theta = estimate.theta;
        }
        self.applied += 1;
        if let Some(ekf) = self.ekf.as_mut() {
            ekf.reset_to(noise.position, noise.heading);
        }
        now
    }

    fn fuse(&mut self, estimate: &Pose, now: Pose, noise: FixNoise) -> Pose {
        self.applied += 1;
        match (self.fusion, self.ekf.as_mut()) {
            (Fusion::Ekf, Some(ekf)) => ekf.update(estimate, &now, noise.position, noise.heading),
            (_, ekf) => {
                if let Some(ekf) = ekf {
                    ekf.reset_to(noise.position, noise.heading);
                }
                now
            }
        }
    }
}

/// A fix of the pose at the instant the estimate was `then`, carried to the
/// instant the estimate is `now` by the motion measured in between:
/// `fix ⊕ (then⁻¹ ⊕ now)`.
pub fn carry(fix: &Pose, then: &Pose, now: &Pose) -> Pose {
    fix.compose(&then.between(now))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::wrap_angle;
    use proptest::prelude::*;

    fn pose() -> impl Strategy<Value = Pose> {
        (-20.0..20.0f64, -20.0..20.0f64, -7.0..7.0f64).prop_map(|(x, y, theta)| Pose {
            x,
            y,
            theta,
        })
    }

    fn close(a: &Pose, b: &Pose, tol: f64) -> bool {
        (a.x - b.x).abs() < tol
            && (a.y - b.y).abs() < tol
            && wrap_angle(a.theta - b.theta).abs() < tol
    }

    proptest! {
        /// An estimate off the truth by any rigid error `E` (estimate =
        /// `E ⊕ truth`, the odometry exact since the fix was taken): a fix
        /// of the true pose then, carried to now, is the true pose now,
        /// whatever the latency's motion.
        #[test]
        fn a_late_fix_carried_by_exact_odometry_is_the_truth_now(
            error in pose(), truth_then in pose(), truth_now in pose()
        ) {
            let then = error.compose(&truth_then);
            let now = error.compose(&truth_now);
            let carried = carry(&truth_then, &then, &now);
            prop_assert!(close(&carried, &truth_now, 1e-9), "{carried:?} vs {truth_now:?}");
        }

        /// Reset fusion: a fix within the gate replaces the estimate (its
        /// heading kept when the fix has none); one beyond it is refused,
        /// counted, the estimate unchanged; the distance is the closed form
        /// `‖ν‖²/σ²` for a reset.
        #[test]
        fn the_gate_refuses_exactly_the_implausible(
            est in pose(), dx in -1.0..1.0f64, dy in -1.0..1.0f64, sd in 0.01..0.5f64
        ) {
            let mut f = FixFusion::new(Fusion::Reset, true);
            let fix = Pose { x: est.x + dx, y: est.y + dy, theta: est.theta + 0.3 };
            let noise = FixNoise { position: sd, heading: None };
            let d2 = (dx * dx + dy * dy) / (sd * sd);
            match f.apply(&est, &est, &fix, noise) {
                Ok(p) => {
                    prop_assert!(d2 <= GATE_2DOF * (1.0 + 1e-9), "{d2}");
                    let want = Pose { theta: est.theta, ..fix };
                    prop_assert!(close(&p, &want, 1e-9), "{:?} vs {:?}", p, want);
                    prop_assert_eq!((f.applied(), f.gated()), (1, 0));
                }
                Err(g) => {
                    prop_assert!(d2 > GATE_2DOF * (1.0 - 1e-9), "{d2}");
                    prop_assert!((g.distance_sq - d2).abs() <= 1e-9 * d2);
                    prop_assert_eq!((f.applied(), f.gated()), (0, 1));
                }
            }
            // Without the gate everything is applied.
            let mut open = FixFusion::new(Fusion::Reset, false);
            prop_assert!(open.apply(&est, &est, &fix, noise).is_ok());
        }
    }

    #[test]
    fn an_ekf_refuses_an_outlier_and_keeps_its_covariance() {
        let mut f = FixFusion::new(Fusion::Ekf, true);
        let start = Pose::default();
        for _ in 0..100 {
            f.ekf_mut()
                .expect("ekf")
                .predict(&start, 0.01, 0.0, 0.2, [1e-6, 1e-6]);
        }
        let p = f.covariance().expect("ekf");
        let est = Pose {
            x: 1.0,
            ..Pose::default()
        };
        let noise = FixNoise {
            position: 0.01,
            heading: None,
        };
        // 1 m off with σ ≈ 1 cm: refused, nothing changed.
        let far = Pose { x: 2.0, ..est };
        let g = f.apply(&est, &est, &far, noise).expect_err("gated");
        assert!(g.distance_sq > 1e3 && g.threshold == GATE_2DOF, "{g:?}");
        assert_eq!(f.covariance(), Some(p));
        // 5 mm off: fused, the covariance shrinks.
        let near = Pose { x: 1.005, ..est };
        let out = f.apply(&est, &est, &near, noise).expect("applied");
        assert!(out.x > 1.0 && out.x < 1.005);
        assert!(f.covariance().expect("ekf")[0][0] < p[0][0]);
        assert_eq!((f.applied(), f.gated()), (1, 1));
    }
}
