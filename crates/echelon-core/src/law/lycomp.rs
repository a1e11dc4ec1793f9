//! Where the follower wants its leader: `L_X`, `L_Y` and the curvature
//! compensation `L_Ycomp` (paper eqs. 4–6, Definition 1, Remark 3).
//!
//! `L_X = L_Xoff + L` and `L_Y = L_Yoff + L_Ycomp`, where `L_Ycomp` keeps the
//! follower on a path "parallel" to its leader's when the leader turns. The
//! functions here are generic over dual numbers: with `f64` they give `L_Ycomp`,
//! with `Dual2<f64>` built from the reference's derivatives they give the exact
//! `L̇_Y` and `L̈_Y` by automatic differentiation.

use num_dual::{Dual2, DualNum};

use crate::check;
use crate::error::ParamError;
use crate::law::control::{LeaderMotion, Offset};
use crate::reference::{Jet, STANDSTILL};

/// How `L_Ycomp` is computed (`lycomp = "exact"`, `"fit"` or `"none"` in a scenario).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(
    feature = "serde",
    derive(serde::Deserialize, serde::Serialize, schemars::JsonSchema)
)]
#[cfg_attr(feature = "serde", serde(rename_all = "kebab-case"))]
pub enum LyComp {
    /// Eq. 5 in curvature form: exact, smooth except where `|κ| L_Xoff = 1`.
    Exact,
    /// Eq. 6, the paper's smooth fit (valid for `0.1 < L_Xoff < 0.9`).
    Fit,
    /// No compensation: `L_Ycomp = 0`.
    None,
}

/// Whether `L̇_Y` and `L̈_Y` enter the law (`ly_derivatives = "neglect"` or
/// `"exact"` in a scenario).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(
    feature = "serde",
    derive(serde::Deserialize, serde::Serialize, schemars::JsonSchema)
)]
#[cfg_attr(feature = "serde", serde(rename_all = "kebab-case"))]
pub enum LyDerivatives {
    /// Neglected (`L̇_Y = L̈_Y = 0`), as the paper's simulations and experiments do (Remark 3).
    Neglect,
    /// Exact, from the reference's 3rd and 4th derivatives (analytic references only).
    Exact,
}

/// Eq. 5, in terms of the leader's speed `V_d` and turn rate `ω_d`
/// (curvature `κ = ω_d / V_d`, `λ = L_Xoff`):
///
/// ```text
/// L_Ycomp = κ λ² / (1 + √(1 − κ²λ²))    if |κ| λ ≤ 1
/// L_Ycomp = 1/κ = R_C                    otherwise
/// ```
///
/// This equals the paper's `sign(R_C)(|R_C| − √(R_C² − λ²))` without its
/// cancellation for gentle curves and without an infinity for straight lines
/// (where it is 0).
pub fn exact<D: DualNum<Primitive = f64> + Copy>(speed: D, turn_rate: D, lambda: f64) -> D {
    let (v, w) = (speed.re(), turn_rate.re());
    if w == 0.0 {
        return D::from(0.0);
    }
    if w.abs() * lambda >= v {
        // |κ| λ ≥ 1: the leader turns tighter than L_Xoff; truncated to R_C.
        return speed / turn_rate;
    }
    let k = turn_rate / speed;
    let kl = k * lambda;
    k * (lambda * lambda) / ((D::from(1.0) - kl * kl).sqrt() + 1.0)
}

/// The three parameters `G`, `δ`, `ε` of the smooth fit, eq. 6.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FitCoefficients {
    /// Gain `G`, m.
    pub g: f64,
    /// Width `δ`, m.
    pub delta: f64,
    /// Spread `ε`, m.
    pub epsilon: f64,
}

impl FitCoefficients {
    /// The paper's polynomials in `λ = L_Xoff` (section 4.1), fitted for `0.1 < λ < 0.9`.
    pub fn paper(lambda: f64) -> FitCoefficients {
        let poly = |c: [f64; 5]| c.iter().fold(0.0, |acc, &k| acc * lambda + k);
        FitCoefficients {
            g: poly([-4.0501, 9.8511, -6.2869, 1.6154, -0.0772]),
            epsilon: poly([6.9639, -14.778, 8.7458, -0.0207, 0.1361]),
            delta: poly([-8.3333, 15.37, -7.8889, 1.7657, -0.0311]),
        }
    }

    /// The range of `L_Xoff` over which the paper's polynomials were fitted.
    pub const PAPER_RANGE: (f64, f64) = (0.1, 0.9);
}

/// Eq. 6, the paper's smooth approximation of eq. 5, with `R_C = V_d/ω_d`
/// (taken as 0 for a straight line, where the fit is 0 too):
///
/// ```text
/// L_Ycomp ≈ 2G (2 atan(R_C/δ) − atan((R_C − ε)/δ) − atan((R_C + ε)/δ))
/// ```
pub fn fit<D: DualNum<Primitive = f64> + Copy>(
    speed: D,
    turn_rate: D,
    coeffs: &FitCoefficients,
) -> D {
    if turn_rate.re() == 0.0 {
        return D::from(0.0);
    }
    let rc = speed / turn_rate;
    fit_rc(rc, coeffs)
}

/// Eq. 6 as a function of the radius of curvature `R_C`.
pub fn fit_rc<D: DualNum<Primitive = f64> + Copy>(rc: D, c: &FitCoefficients) -> D {
    let inv = 1.0 / c.delta;
    ((rc * inv).atan() * 2.0 - ((rc - c.epsilon) * inv).atan() - ((rc + c.epsilon) * inv).atan())
        * (2.0 * c.g)
}

/// A follower's desired placement of its leader as written: unchecked.
/// [`Placement::new`] checks it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlacementSpec {
    /// `L_Xoff`, m (finite; the scenario's `offset.x`).
    pub lx_off: f64,
    /// `L_Yoff`, m (finite; the scenario's `offset.y`).
    pub ly_off: f64,
    /// `L`, m: a finite number `> 0` with `L_X = L_Xoff + L > 0`.
    pub l: f64,
    /// How `L_Ycomp` is computed.
    pub comp: LyComp,
    /// Whether `L̇_Y`, `L̈_Y` are used.
    pub derivatives: LyDerivatives,
}

/// The frame an offset is written in (`offset.frame` in a scenario).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum OffsetFrame {
    /// The paper's (Definition 1, eq. 7): the leader at `[L_X, L_Y]` in the
    /// follower's frame. The follower's heading places its slot: a robot
    /// turned away from its leader's heading holds a slot turned with it,
    /// and realigns through the internal dynamics
    /// `θ̇ = V_d sin(θ_d − θ) / L_X` (docs/control-law.md, "Offsets in the
    /// leader's frame").
    #[default]
    Follower,
    /// A rigid formation: the slot `q = p_d − R(θ_d)ᵀ [L_Xoff, L_Yoff]` is
    /// fixed in the leader's frame (heading `θ_d`), whatever the follower's
    /// heading, and the point `L` ahead of the follower tracks it (pure
    /// tracking, eqs. 14–16, of `q`). `L_Ycomp` does not apply.
    Leader,
}

/// A follower's desired placement of its leader: offsets, `L`, and how `L_Y`
/// follows the leader's curvature.
///
/// Built through [`Placement::new`], [`Placement::tracking`] or
/// [`Placement::leader_frame`], which check it, so a `Placement` in hand
/// always has `L_X > 0` (`L_X = L` in the leader's frame).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Placement {
    spec: PlacementSpec,
    fit: FitCoefficients,
    frame: OffsetFrame,
}

impl TryFrom<PlacementSpec> for Placement {
    type Error = ParamError;

    fn try_from(spec: PlacementSpec) -> Result<Self, ParamError> {
        Placement::new(spec)
    }
}

impl Placement {
    /// Whether `L̇_Y`, `L̈_Y` are computed exactly (and so needed): exact
    /// derivatives asked for and some `L_Ycomp` to differentiate.
    #[inline]
    pub fn uses_exact_derivatives(&self) -> bool {
        self.spec.derivatives == LyDerivatives::Exact && self.spec.comp != LyComp::None
    }

    /// A leader-follower placement (Definition 1). Refuses non-finite offsets,
    /// `L` that is not a finite number > 0 and `L_X = L_Xoff + L ≤ 0` (eq. 13
    /// divides by `L_X`); errors name `offset.x`, `offset.y` or `l`.
    pub fn new(spec: PlacementSpec) -> Result<Placement, ParamError> {
        let p = Placement {
            spec,
            fit: FitCoefficients::paper(spec.lx_off),
            frame: OffsetFrame::Follower,
        };
        p.check()?;
        Ok(p)
    }

    /// A slot fixed in the leader's frame ([`OffsetFrame::Leader`]): the
    /// point `l` ahead of the follower tracks `p_d − R(θ_d)ᵀ [lx_off,
    /// ly_off]`. The slot may lie anywhere (ahead of the leader too); the law
    /// is pure tracking, so `L_X = L`. Refuses non-finite offsets and `l`
    /// that is not a finite number `> 0`; errors name `offset.x`, `offset.y`
    /// or `l`.
    pub fn leader_frame(lx_off: f64, ly_off: f64, l: f64) -> Result<Placement, ParamError> {
        check::positive("l", l)?;
        check::finite("offset.x", lx_off)?;
        check::finite("offset.y", ly_off)?;
        Ok(Placement {
            spec: PlacementSpec {
                lx_off,
                ly_off,
                l,
                comp: LyComp::None,
                derivatives: LyDerivatives::Neglect,
            },
            fit: FitCoefficients::paper(lx_off),
            frame: OffsetFrame::Leader,
        })
    }

    /// The frame the offset is written in.
    #[inline]
    pub const fn frame(&self) -> OffsetFrame {
        self.frame
    }

    /// Whether the law needs the reference's jerk `p⃛_d` (and snap): exact
    /// `L̇_Y`, `L̈_Y`, or a slot in the leader's frame, whose acceleration
    /// holds the leader's angular acceleration `ω̇_d`.
    #[inline]
    pub fn needs_jerk(&self) -> bool {
        self.uses_exact_derivatives() || self.frame == OffsetFrame::Leader
    }

    /// The placement as written (what [`Placement::new`] takes back for the
    /// follower's frame; [`Placement::frame`] says which).
    #[inline]
    pub const fn spec(&self) -> PlacementSpec {
        self.spec
    }

    /// `L_Xoff`, m.
    #[inline]
    pub const fn lx_off(&self) -> f64 {
        self.spec.lx_off
    }

    /// `L_Yoff`, m.
    #[inline]
    pub const fn ly_off(&self) -> f64 {
        self.spec.ly_off
    }

    /// `L > 0`, m: keeps `L_X > 0` (eq. 13 divides by it).
    #[inline]
    pub const fn l(&self) -> f64 {
        self.spec.l
    }

    /// How `L_Ycomp` is computed (the field `comp`; [`Placement::comp`]
    /// computes it).
    #[inline]
    pub const fn lycomp(&self) -> LyComp {
        self.spec.comp
    }

    /// Whether `L̇_Y`, `L̈_Y` are used.
    #[inline]
    pub const fn derivatives(&self) -> LyDerivatives {
        self.spec.derivatives
    }

    /// Fit coefficients for `lx_off` (used with [`LyComp::Fit`]).
    #[inline]
    pub const fn fit(&self) -> FitCoefficients {
        self.fit
    }

    /// [`Placement::new`]'s checks.
    fn check(&self) -> Result<(), ParamError> {
        check::positive("l", self.spec.l)?;
        check::finite("offset.x", self.spec.lx_off)?;
        check::finite("offset.y", self.spec.ly_off)?;
        let lx = self.lx();
        check::require(
            "offset.x",
            self.spec.lx_off,
            lx > 0.0,
            format!("makes L_X = L_Xoff + L = {lx} m, which must be > 0 (eq. 13 divides by L_X)"),
        )?;
        if self.spec.comp == LyComp::Fit {
            let FitCoefficients { g, epsilon, delta } = self.fit;
            check::require(
                "offset.x",
                self.spec.lx_off,
                g.is_finite() && epsilon.is_finite() && delta.is_finite() && delta != 0.0,
                "is too far outside the range of the eq. 6 fit (use lycomp = \"exact\")",
            )?;
        }
        Ok(())
    }

    /// Pure tracking (eqs. 14–16): `L_X = L`, `L_Y = 0`; the point `L` ahead of
    /// the robot tracks `p_d`. Refuses `L` that is not a finite number > 0.
    pub fn tracking(l: f64) -> Result<Placement, ParamError> {
        Placement::new(PlacementSpec {
            lx_off: 0.0,
            ly_off: 0.0,
            l,
            comp: LyComp::None,
            derivatives: LyDerivatives::Neglect,
        })
    }

    /// `L_X = L_Xoff + L` (`L` in the leader's frame: pure tracking).
    #[inline]
    pub fn lx(&self) -> f64 {
        match self.frame {
            OffsetFrame::Follower => self.spec.lx_off + self.spec.l,
            OffsetFrame::Leader => self.spec.l,
        }
    }

    /// `L_Ycomp` for the leader's speed and turn rate (either type: `f64` or dual).
    #[inline]
    pub fn comp<D: DualNum<Primitive = f64> + Copy>(&self, speed: D, turn_rate: D) -> D {
        match self.spec.comp {
            LyComp::Exact => exact(speed, turn_rate, self.spec.lx_off),
            LyComp::Fit => fit(speed, turn_rate, &self.fit),
            LyComp::None => D::from(0.0),
        }
    }

    /// `L_X, L_Y, L̇_Y, L̈_Y` for an analytic reference (`jet` must hold up to `p⁗`
    /// when derivatives are exact).
    #[inline]
    pub fn offset_for_reference(&self, jet: &Jet) -> Offset {
        match (self.spec.comp, self.spec.derivatives) {
            (LyComp::None, _) => self.offset(0.0, 0.0, 0.0),
            (_, LyDerivatives::Neglect) => {
                self.offset(self.comp(jet.speed(), jet.turn_rate()), 0.0, 0.0)
            }
            (_, LyDerivatives::Exact) => {
                // Speed and turn rate as second-order jets in time.
                let dx = Dual2::new(jet.dp[0], jet.ddp[0], jet.d3p[0]);
                let dy = Dual2::new(jet.dp[1], jet.ddp[1], jet.d3p[1]);
                let ddx = Dual2::new(jet.ddp[0], jet.d3p[0], jet.d4p[0]);
                let ddy = Dual2::new(jet.ddp[1], jet.d3p[1], jet.d4p[1]);
                let v2 = dx * dx + dy * dy;
                if v2.re <= STANDSTILL * STANDSTILL {
                    return self.offset(0.0, 0.0, 0.0);
                }
                let comp = self.comp(v2.sqrt(), (dx * ddy - dy * ddx) / v2);
                self.offset(comp.re, comp.v1, comp.v2)
            }
        }
    }

    /// `L_X, L_Y` for a leader that is another robot moving at `v`, `ω`
    /// (`V_d = v_j`, `ω_d = ω_j`; derivatives neglected).
    #[inline]
    pub fn offset_for_robot(&self, v: f64, omega: f64) -> Offset {
        self.offset(self.comp(v.max(0.0), omega), 0.0, 0.0)
    }

    #[inline]
    fn offset(&self, comp: f64, dly: f64, ddly: f64) -> Offset {
        match self.frame {
            OffsetFrame::Follower => Offset {
                lx: self.lx(),
                ly: self.spec.ly_off + comp,
                dly,
                ddly,
            },
            OffsetFrame::Leader => Offset {
                lx: self.spec.l,
                ly: 0.0,
                dly: 0.0,
                ddly: 0.0,
            },
        }
    }

    /// The slot's motion for a leader moving as `m`, heading `theta`, turning
    /// at `omega` and `domega`: `m` itself in the follower's frame; in the
    /// leader's frame `q = p − R o`, `q̇ = ṗ − ω J R o`,
    /// `q̈ = p̈ − ω̇ J R o + ω² R o`, with `o = [L_Xoff, L_Yoff]`, `R` the
    /// rotation by `theta` and `J` the rotation by a quarter turn.
    #[inline]
    pub fn slot(&self, m: &LeaderMotion, theta: f64, omega: f64, domega: f64) -> LeaderMotion {
        if self.frame == OffsetFrame::Follower {
            return *m;
        }
        let (s, c) = theta.sin_cos();
        let (x, y) = (self.spec.lx_off, self.spec.ly_off);
        // R o, and J R o (a quarter turn to the left).
        let ro = [c * x - s * y, s * x + c * y];
        let jro = [-ro[1], ro[0]];
        let w2 = omega * omega;
        LeaderMotion {
            p: [m.p[0] - ro[0], m.p[1] - ro[1]],
            dp: [m.dp[0] - omega * jro[0], m.dp[1] - omega * jro[1]],
            ddp: [
                m.ddp[0] - domega * jro[0] + w2 * ro[0],
                m.ddp[1] - domega * jro[1] + w2 * ro[1],
            ],
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Eq. 5 exactly as printed, in terms of `R_C`.
    fn eq5(rc: f64, lambda: f64) -> f64 {
        if rc.is_infinite() {
            0.0
        } else if rc.abs() >= lambda {
            rc.signum() * (rc.abs() - (rc * rc - lambda * lambda).sqrt())
        } else {
            rc
        }
    }

    #[test]
    fn exact_equals_eq_5_in_both_branches_and_at_infinity() {
        for &lambda in &[0.1, 0.3, 0.5, 0.9, 2.0] {
            for &rc in &[
                -50.0, -5.0, -1.0, -0.51, -0.3, -0.05, 0.02, 0.25, 0.49, 0.5, 0.7, 1.3, 5.0, 1e3,
            ] {
                let v = 0.7;
                let w = v / rc;
                let got: f64 = exact(v, w, lambda);
                let want = eq5(rc, lambda);
                assert!(
                    (got - want).abs() <= 1e-12 * (1.0 + want.abs()),
                    "λ = {lambda}, R_C = {rc}: {got} vs {want}"
                );
            }
            // R_C = ∞: a straight line, ω_d = 0.
            assert_eq!(exact(0.7f64, 0.0, lambda), eq5(f64::INFINITY, lambda));
        }
    }

    #[test]
    fn exact_is_continuous_at_the_branch_point() {
        let lambda = 0.5;
        let rc = lambda;
        let below = exact(1.0f64, 1.0 / (rc * (1.0 + 1e-12)), lambda);
        let above = exact(1.0f64, 1.0 / (rc * (1.0 - 1e-12)), lambda);
        assert!((below - above).abs() < 1e-6);
        assert!((below - lambda).abs() < 1e-6);
    }

    #[test]
    fn fit_is_the_papers_formula_and_has_the_documented_error() {
        let c = FitCoefficients::paper(0.5);
        let rc: f64 = 5.0;
        let want = 2.0
            * c.g
            * (2.0 * (rc / c.delta).atan()
                - ((rc - c.epsilon) / c.delta).atan()
                - ((rc + c.epsilon) / c.delta).atan());
        assert!((fit(0.5f64, 0.1, &c) - want).abs() < 1e-15);
        // control-law.md: at λ = 0.5, R_C = 5, the fit gives ≈ 0.001 m where eq. 5 gives ≈ 0.025 m.
        assert!(
            (fit(0.5f64, 0.1, &c) - 0.001).abs() < 5e-4,
            "{}",
            fit(0.5, 0.1, &c)
        );
        assert!((exact(0.5f64, 0.1, 0.5) - 0.025).abs() < 2e-4);
        assert_eq!(fit(0.5f64, 0.0, &c), 0.0);
    }

    #[test]
    fn exact_derivatives_match_the_chain_rule() {
        // L_Ycomp(κ(t)) with κ varying: compare the dual result to the chain rule.
        let lambda = 0.4;
        let (k, dk, ddk) = (0.8, 0.3, -0.2);
        let kd = Dual2::new(k, dk, ddk);
        let got = exact(Dual2::new(1.0, 0.0, 0.0), kd, lambda);
        // f(κ) = κλ²/(1+√(1−κ²λ²)) = (1 − √(1−κ²λ²))/κ
        let f = |k: f64| (1.0 - (1.0 - k * k * lambda * lambda).sqrt()) / k;
        let h = 1e-4;
        let f1 = (f(k + h) - f(k - h)) / (2.0 * h);
        let f2 = (f(k + h) - 2.0 * f(k) + f(k - h)) / (h * h);
        assert!((got.re - f(k)).abs() < 1e-14);
        assert!((got.v1 - f1 * dk).abs() < 1e-8);
        assert!((got.v2 - (f2 * dk * dk + f1 * ddk)).abs() < 1e-6);
    }

    #[test]
    fn tracking_placement_is_l_ahead() {
        let p = Placement::tracking(0.05).unwrap();
        let o = p.offset_for_robot(1.0, 0.5);
        assert_eq!((o.lx, o.ly, o.dly, o.ddly), (0.05, 0.0, 0.0, 0.0));
    }
}
