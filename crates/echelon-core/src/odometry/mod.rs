//! Odometry (paper section 6): wheel encoders, dead reckoning, error models,
//! absolute position fixes and the estimate the controller acts on.
//!
//! Each sample the encoders give the wheels' displacements `Δr`, `Δl`; dead
//! reckoning integrates them (eqs. 21–22). The robot's true motion comes from
//! the plant, so everything that makes the encoders lie — the paper's additive
//! `ζ` (Assumption 1, eq. 23), Borenstein's unequal wheel diameters `E_d` and
//! wheelbase error `E_b`, random slip, tick quantization — makes the estimate
//! drift from the truth. Absolute fixes (every `N` samples or `T` seconds, with
//! noise and latency) reset the estimate (the paper) or feed an EKF.
//!
//! Theorem 2's bound and Borenstein's UMBmark are studies above the kernel
//! (`echelon::odometry::{bound, umbmark}`).

mod ekf;
mod errors;
mod fixes;
pub mod fuse;
mod odometer;

use crate::check;
use crate::error::ParamError;
use crate::math::sinc;
use crate::model::Pose;

pub use ekf::Ekf;
pub use errors::{ErrorModel, ZetaModel};
pub use fixes::{FixSchedule, FixSpec, Fusion};
pub use odometer::Odometer;

/// Linear displacements of the two wheels over one sample, m.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct WheelDisplacement {
    /// Right wheel `Δr`.
    pub right: f64,
    /// Left wheel `Δl`.
    pub left: f64,
}

impl WheelDisplacement {
    /// `Δ = (Δr + Δl)/2` and `Θ = (Δr − Δl)/(2l)` (eq. 21).
    #[inline]
    pub fn to_motion(self, half_wheelbase: f64) -> (f64, f64) {
        (
            0.5 * (self.right + self.left),
            (self.right - self.left) / (2.0 * half_wheelbase),
        )
    }
}

/// One dead-reckoning update (eq. 22) by the linear displacement `Δ` and the
/// heading change `Θ`, along the exact arc. Eq. 22's `(Δ/Θ)(sin θₙ − sin θₙ₋₁)` is
/// computed as `Δ sinc(Θ/2) cos(θₙ₋₁ + Θ/2)`, which is the same number without the
/// division (and is eq. 22's straight-line branch at `Θ = 0`).
#[inline]
pub fn arc_update(pose: &Pose, delta: f64, big_theta: f64) -> Pose {
    let chord = delta * sinc(0.5 * big_theta);
    let (s, c) = (pose.theta + 0.5 * big_theta).sin_cos();
    Pose {
        x: pose.x + chord * c,
        y: pose.y + chord * s,
        theta: pose.theta + big_theta,
    }
}

/// The inverse of [`arc_update`]: the `(Δ, Θ)` of the arc from `from` to
/// `to` (a motion that is not an arc from `from`'s heading, e.g. a sideways
/// slip, gets the arc with the same chord length and heading change; the
/// sign of `Δ` is that of the chord along the arc's mid heading). For `|Θ| <
/// 2π`.
pub fn arc_motion(from: &Pose, to: &Pose) -> (f64, f64) {
    let big_theta = to.theta - from.theta;
    let (dx, dy) = (to.x - from.x, to.y - from.y);
    let (s, c) = (from.theta + 0.5 * big_theta).sin_cos();
    let along = dx * c + dy * s;
    let chord = dx.hypot(dy).copysign(along);
    (chord / sinc(0.5 * big_theta), big_theta)
}

/// Dead reckoning from wheel displacements: eq. 21 then eq. 22.
#[inline]
pub fn dead_reckon(pose: &Pose, d: WheelDisplacement, half_wheelbase: f64) -> Pose {
    let (delta, big_theta) = d.to_motion(half_wheelbase);
    arc_update(pose, delta, big_theta)
}

/// One robot's odometry: sampling period, errors and fixes. Built through
/// [`OdometrySpec::new`], which checks that they fit together.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OdometrySpec {
    period: f64,
    errors: ErrorModel,
    fixes: Option<FixSpec>,
    /// Samples between fixes (0: no fixes).
    fix_every: u64,
}

impl OdometrySpec {
    /// A robot's odometry sampled every `period` seconds (a finite number
    /// > 0), refusing fixes that are not a whole number of samples apart.
    pub fn new(
        period: f64,
        errors: ErrorModel,
        fixes: Option<FixSpec>,
    ) -> Result<OdometrySpec, ParamError> {
        check::positive("period", period)?;
        let fix_every = match &fixes {
            None => 0,
            Some(f) => f.samples_between(period)?,
        };
        Ok(OdometrySpec {
            period,
            errors,
            fixes,
            fix_every,
        })
    }

    /// Sampling period of the encoders, s (a whole multiple of the simulation step).
    #[inline]
    pub const fn period(&self) -> f64 {
        self.period
    }

    /// What makes the encoders lie.
    #[inline]
    pub const fn errors(&self) -> ErrorModel {
        self.errors
    }

    /// Absolute fixes, if any.
    #[inline]
    pub const fn fixes(&self) -> Option<FixSpec> {
        self.fixes
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        /// `arc_motion` inverts `arc_update` for any arc (forward or
        /// backward, straight or turning, from any pose): the same `(Δ, Θ)`
        /// back, and the same pose reached again.
        #[test]
        fn arc_motion_inverts_arc_update(
            x in -50.0..50.0f64, y in -50.0..50.0f64, theta in -20.0..20.0f64,
            delta in -2.0..2.0f64, big_theta in -3.0..3.0f64
        ) {
            let from = Pose { x, y, theta };
            let to = arc_update(&from, delta, big_theta);
            let (d, b) = arc_motion(&from, &to);
            prop_assert!((b - big_theta).abs() < 1e-12);
            prop_assert!((d - delta).abs() < 1e-9 * (1.0 + delta.abs()), "{d} vs {delta}");
            let again = arc_update(&from, d, b);
            prop_assert!((again.x - to.x).abs() < 1e-9 && (again.y - to.y).abs() < 1e-9);
        }
    }

    #[test]
    fn straight_and_turn_in_place() {
        let p = Pose::default();
        let q = dead_reckon(
            &p,
            WheelDisplacement {
                right: 1.0,
                left: 1.0,
            },
            0.2,
        );
        assert_eq!((q.x, q.y, q.theta), (1.0, 0.0, 0.0));
        let q = dead_reckon(
            &p,
            WheelDisplacement {
                right: 0.1,
                left: -0.1,
            },
            0.2,
        );
        assert!(q.x.abs() < 1e-15 && q.y.abs() < 1e-15 && (q.theta - 0.5).abs() < 1e-15);
    }

    #[test]
    fn arc_update_is_eq_22() {
        let p = Pose {
            x: 1.0,
            y: -2.0,
            theta: 0.7,
        };
        let (delta, th) = (0.3, 0.2);
        let q = arc_update(&p, delta, th);
        let r = delta / th;
        assert!((q.x - (p.x + r * ((0.7f64 + th).sin() - 0.7f64.sin()))).abs() < 1e-15);
        assert!((q.y - (p.y - r * ((0.7f64 + th).cos() - 0.7f64.cos()))).abs() < 1e-15);
    }
}
