//! Theorem 2: how far odometry errors can push `z`, and so how often an
//! absolute position fix is needed.
//!
//! With the law acting on estimates (eqs. 32–35), `N` dead-reckoned samples
//! since the last fix and an error of at most `ζ` per axis per sample (eqs. 30–31),
//! `z` is uniformly ultimately bounded:
//!
//! ```text
//! ‖z‖ ≤ (√2 K_e N ζ / (K_z γ)) · √(K_z² + ω_M²),    γ ∈ (0, 1),  |ω| ≤ ω_M
//! ```
//!
//! The bound is on the true `z` (from the true pose). Inverting it gives the
//! largest `N`, hence the longest fix period `N T_s`.

use serde::Serialize;

use crate::error::ParamError;

/// The quantities Theorem 2 depends on.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Theorem2 {
    /// `K_e > 0`.
    pub ke: f64,
    /// `K_z > 0`.
    pub kz: f64,
    /// `ζ > 0`: the largest odometry error per axis per sample, m.
    pub zeta: f64,
    /// `ω_M ≥ 0`: the largest angular speed, rad/s.
    pub omega_max: f64,
    /// `γ ∈ (0, 1)`: the share of `K_z‖z‖²` spent on dominating the error term.
    pub gamma: f64,
}

/// What `echelon bound --json` prints.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct BoundReport {
    /// The ultimate bound on ‖z‖, m/s.
    pub z_bound: f64,
    /// Samples between fixes.
    pub steps: u64,
    /// `N T_s`, s (`None` without a sample period).
    pub fix_period_s: Option<f64>,
}

fn check(field: &'static str, v: f64, ok: bool, reason: &'static str) -> Result<(), ParamError> {
    if v.is_finite() && ok {
        Ok(())
    } else {
        Err(ParamError::new(field, v, reason))
    }
}

/// The hypotheses both forms of Theorem 2 share: `K_e, ζ > 0`, `γ ∈ (0, 1)`.
fn shared_hypotheses(ke: f64, zeta: f64, gamma: f64) -> Result<(), ParamError> {
    check("ke", ke, ke > 0.0, "must be > 0 (Theorem 2 needs K_e > 0)")?;
    check(
        "zeta",
        zeta,
        zeta > 0.0,
        "must be > 0 (the odometry error per sample)",
    )?;
    check(
        "gamma",
        gamma,
        gamma > 0.0 && gamma < 1.0,
        "must be in (0, 1) (Theorem 2's γ)",
    )
}

/// The largest `N` with `N · per ≤ max` (the inverse of a bound linear in `N`).
fn max_multiple(field: &'static str, max: f64, per: f64) -> Result<u64, ParamError> {
    check(field, max, max > 0.0, "must be > 0")?;
    let mut n = (max / per).floor();
    if n >= u64::MAX as f64 {
        return Err(ParamError::new(
            field,
            max,
            "allows more samples than can be counted: ζ is too small to matter",
        ));
    }
    // Guard the floor against rounding on either side.
    while n > 0.0 && n * per > max {
        n -= 1.0;
    }
    while (n + 1.0) * per <= max {
        n += 1.0;
    }
    Ok(n as u64)
}

impl Theorem2 {
    /// Checks the theorem's hypotheses: `K_e, K_z, ζ > 0`, `ω_M ≥ 0`, `γ ∈ (0, 1)`.
    pub fn new(
        ke: f64,
        kz: f64,
        zeta: f64,
        omega_max: f64,
        gamma: f64,
    ) -> Result<Theorem2, ParamError> {
        shared_hypotheses(ke, zeta, gamma)?;
        check("kz", kz, kz > 0.0, "must be > 0 (Theorem 2 needs K_z > 0)")?;
        check("omega_max", omega_max, omega_max >= 0.0, "must be ≥ 0")?;
        Ok(Theorem2 {
            ke,
            kz,
            zeta,
            omega_max,
            gamma,
        })
    }

    /// The bound per sample of dead reckoning: `√2 K_e ζ √(K_z² + ω_M²) / (K_z γ)`.
    pub fn per_step(&self) -> f64 {
        std::f64::consts::SQRT_2 * self.ke * self.zeta * self.kz.hypot(self.omega_max)
            / (self.kz * self.gamma)
    }

    /// The ultimate bound on ‖z‖ after `steps` samples without a fix.
    pub fn z_bound(&self, steps: u64) -> f64 {
        steps as f64 * self.per_step()
    }

    /// The largest `N` with `z_bound(N) ≤ max_z` (0 if even one sample exceeds it).
    pub fn max_steps(&self, max_z: f64) -> Result<u64, ParamError> {
        max_multiple("max_z", max_z, self.per_step())
    }

    /// Forward: the bound for `steps`, with the fix period if `ts` is given.
    pub fn forward(&self, steps: u64, ts: Option<f64>) -> BoundReport {
        BoundReport {
            z_bound: self.z_bound(steps),
            steps,
            fix_period_s: ts.map(|t| t * steps as f64),
        }
    }

    /// Inverse: the largest `N` for `max_z`, and the fix period `N T_s`.
    pub fn inverse(&self, max_z: f64, ts: Option<f64>) -> Result<BoundReport, ParamError> {
        let steps = self.max_steps(max_z)?;
        Ok(self.forward(steps, ts))
    }
}

/// Theorem 2 re-derived for the kinematic law ([`crate::kinematic`]) on an
/// ideal base (`docs/control-law.md`, "Theorem 2 for the kinematic law").
///
/// The controller sees `ê = e − ẽ` with `ẽ = R p̃`, `‖ẽ‖ ≤ √2 N ζ` (eq. 30;
/// heading exact by Assumption 1). The base moves at the command, so the true
/// `z = ξ − ξ*(e) = K_e ẽ` and `ė = −S e − K_e e + K_e ẽ`:
///
/// ```text
/// ‖z‖ ≤ √2 K_e N ζ                 at every instant (no K_z, no ω_M)
/// ‖e‖ ≤ √2 N ζ / γ                 ultimately,  γ ∈ (0, 1)
/// ```
///
/// The `z` bound is the dynamic law's `√2 K_e N ζ √(K_z² + ω_M²)/(K_z γ)` in
/// the limit `K_z → ∞`, `γ → 1`, and is attained under the paper's worst case
/// (eq. 31). The `e` bound does not depend on `K_e`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct KinematicTheorem2 {
    /// `K_e > 0`.
    pub ke: f64,
    /// `ζ > 0`: the largest odometry error per axis per sample, m.
    pub zeta: f64,
    /// `γ ∈ (0, 1)`: the share of `K_e‖e‖²` spent on dominating the error term.
    pub gamma: f64,
}

impl KinematicTheorem2 {
    /// Checks the hypotheses: `K_e, ζ > 0`, `γ ∈ (0, 1)`.
    pub fn new(ke: f64, zeta: f64, gamma: f64) -> Result<KinematicTheorem2, ParamError> {
        shared_hypotheses(ke, zeta, gamma)?;
        Ok(KinematicTheorem2 { ke, zeta, gamma })
    }

    /// The bound on the true ‖z‖ after `steps` samples without a fix,
    /// `√2 K_e N ζ`, m/s: it holds at every instant, not only ultimately.
    pub fn z_bound(&self, steps: u64) -> f64 {
        std::f64::consts::SQRT_2 * self.ke * self.zeta * steps as f64
    }

    /// The bound per sample on ‖e‖: `√2 ζ / γ`, m.
    pub fn e_per_step(&self) -> f64 {
        std::f64::consts::SQRT_2 * self.zeta / self.gamma
    }

    /// The ultimate bound on ‖e‖ after `steps` samples without a fix, m.
    pub fn e_bound(&self, steps: u64) -> f64 {
        steps as f64 * self.e_per_step()
    }

    /// The largest `N` with `e_bound(N) ≤ max_e`: how often a fix is needed to
    /// keep the formation within `max_e` of its place.
    pub fn max_steps(&self, max_e: f64) -> Result<u64, ParamError> {
        max_multiple("max_e", max_e, self.e_per_step())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn the_papers_formula() {
        let t = Theorem2::new(1.5, 10.0, 1e-4, 1.0, 0.5).unwrap();
        let want = 2f64.sqrt() * 1.5 * 1000.0 * 1e-4 * (100.0f64 + 1.0).sqrt() / (10.0 * 0.5);
        assert!((t.z_bound(1000) - want).abs() < 1e-15);
    }

    #[test]
    fn hypotheses_are_enforced() {
        assert_eq!(
            Theorem2::new(1.5, 10.0, 1e-4, 1.0, 1.0).unwrap_err().field,
            "gamma"
        );
        assert_eq!(
            Theorem2::new(1.5, 10.0, 1e-4, 1.0, 0.0).unwrap_err().field,
            "gamma"
        );
        assert_eq!(
            Theorem2::new(0.0, 10.0, 1e-4, 1.0, 0.5).unwrap_err().field,
            "ke"
        );
        assert_eq!(
            Theorem2::new(1.5, -1.0, 1e-4, 1.0, 0.5).unwrap_err().field,
            "kz"
        );
        assert_eq!(
            Theorem2::new(1.5, 10.0, 0.0, 1.0, 0.5).unwrap_err().field,
            "zeta"
        );
        assert_eq!(
            Theorem2::new(1.5, 10.0, 1e-4, f64::NAN, 0.5)
                .unwrap_err()
                .field,
            "omega_max"
        );
    }

    #[test]
    fn the_kinematic_bound_is_the_dynamic_ones_limit() {
        let k = KinematicTheorem2::new(1.5, 1e-4, 0.5).unwrap();
        let want = 2f64.sqrt() * 1.5 * 1000.0 * 1e-4;
        assert!((k.z_bound(1000) - want).abs() < 1e-15);
        assert!((k.e_bound(1000) - 2f64.sqrt() * 0.1 / 0.5).abs() < 1e-15);
        // K_z → ∞, γ → 1 in the dynamic law's bound gives the kinematic z bound.
        let d = Theorem2::new(1.5, 1e9, 1e-4, 2.0, 1.0 - 1e-12).unwrap();
        assert!((d.z_bound(1000) / k.z_bound(1000) - 1.0).abs() < 1e-9);
        assert_eq!(
            KinematicTheorem2::new(0.0, 1e-4, 0.5).unwrap_err().field,
            "ke"
        );
        assert_eq!(
            KinematicTheorem2::new(1.0, -1.0, 0.5).unwrap_err().field,
            "zeta"
        );
        assert_eq!(
            KinematicTheorem2::new(1.0, 1e-4, 1.0).unwrap_err().field,
            "gamma"
        );
        assert_eq!(k.max_steps(0.0).unwrap_err().field, "max_e");
    }

    proptest! {
        /// The kinematic bound's inverse: the largest N whose ‖e‖ bound fits.
        #[test]
        fn kinematic_forward_and_inverse_agree(
            ke in 0.01..20.0f64, zeta in 1e-7..1e-2f64, gamma in 0.01..0.99f64,
            max_e in 1e-4..10.0f64,
        ) {
            let k = KinematicTheorem2::new(ke, zeta, gamma).unwrap();
            let n = k.max_steps(max_e).unwrap();
            prop_assert!(k.e_bound(n) <= max_e);
            prop_assert!(k.e_bound(n + 1) > max_e);
        }

        /// Forward and inverse agree: N = max_steps(b) is the largest N with bound(N) ≤ b.
        #[test]
        fn forward_and_inverse_agree(
            ke in 0.01..20.0f64, kz in 0.01..100.0f64, zeta in 1e-7..1e-2f64,
            omega in 0.0..5.0f64, gamma in 0.01..0.99f64, max_z in 1e-4..10.0f64,
        ) {
            let t = Theorem2::new(ke, kz, zeta, omega, gamma).unwrap();
            let n = t.max_steps(max_z).unwrap();
            prop_assert!(t.z_bound(n) <= max_z);
            prop_assert!(t.z_bound(n + 1) > max_z);
            // and back: the bound for that N, inverted, gives N again.
            if n > 0 {
                prop_assert_eq!(t.max_steps(t.z_bound(n)).unwrap(), n);
            }
        }
    }
}
