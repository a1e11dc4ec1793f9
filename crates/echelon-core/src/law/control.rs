//! The leader-follower backstepping law (paper eqs. 7–13) and pure tracking
//! (eqs. 14–16), as corrected in `docs/control-law.md`.
//!
//! With `R(θ) = [[cos θ, sin θ], [−sin θ, cos θ]]`, `S = [[0, −ω], [ω, 0]]`:
//!
//! ```text
//! e  = R (p − p_d) + [L_X, L_Y]ᵀ                                   (eq. 7)
//! ξ  = [v − ω L_Y, ω L_X]ᵀ
//! ė  = −S e + ξ − R ṗ_d + [0, L̇_Y]ᵀ                                (eq. 8)
//! z  = ξ − (R ṗ_d − [0, L̇_Y]ᵀ − K_e e)                             (eq. 10)
//! ż  = h + B u,   B = [[1/m, −L_Y/J], [0, L_X/J]]
//! h  = [−ω L̇_Y + (L_Y/J) ψ ω − (η/m) v, −(L_X/J) ψ ω]ᵀ
//!      + S R ṗ_d − R p̈_d + [0, L̈_Y]ᵀ + K_e ė                       (eq. 12)
//! u  = B⁻¹ w,  w = −h − K_z z        (paper, eq. 13)
//!              w = −h − K_z z − e    (complete: cancels the cross term eᵀz)
//! ```
//!
//! Along the closed loop `V₂ = ½‖e‖² + ½‖z‖²` obeys
//! `V̇₂ = −K_e‖e‖² + eᵀz − K_z‖z‖²` (paper) or `−K_e‖e‖² − K_z‖z‖²` (complete).
//! Pure tracking is the same law with `L_X = L`, `L_Y = 0` ([`crate::law::lycomp::Placement::tracking`]).

use std::ops::{Add, Mul, Neg, Sub};

use num_dual::DualNum;

use crate::check;
use crate::error::ParamError;
use crate::math::lanes::Real;
use crate::model::{Input, RobotParams, State};
use crate::reference::Jet;

/// The backstepping gains, both finite and > 0: built through [`Gains::new`]
/// (or [`Gains::PAPER`]), so a `Gains` in hand is always a usable one.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Gains {
    ke: f64,
    kz: f64,
}

impl Gains {
    /// The paper's gains: `K_e = 1.5`, `K_z = 10`.
    pub const PAPER: Gains = Gains { ke: 1.5, kz: 10.0 };

    /// Gains for a simulation: both finite and > 0 (eq. 13's `K_e`, `K_z`).
    pub fn new(ke: f64, kz: f64) -> Result<Gains, ParamError> {
        check::positive("ke", ke)?;
        check::positive("kz", kz)?;
        Ok(Gains { ke, kz })
    }

    /// `K_e > 0`: convergence rate of `e` (first step).
    #[inline]
    pub const fn ke(&self) -> f64 {
        self.ke
    }

    /// `K_z > 0`: convergence rate of `z` (second step).
    #[inline]
    pub const fn kz(&self) -> f64 {
        self.kz
    }
}

/// Which form of eq. 13 (`law = "paper"` or `"complete"` in a scenario).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "serde", derive(serde::Deserialize, serde::Serialize))]
#[cfg_attr(feature = "serde", serde(rename_all = "kebab-case"))]
pub enum Variant {
    /// The paper's `u = B⁻¹(−h − K_z z)`: leaves the cross term `eᵀz` in `V̇₂`, so
    /// Theorem 1 needs `K_e K_z > 1/4`.
    #[default]
    Paper,
    /// Textbook backstepping `u = B⁻¹(−h − K_z z − e)`: `V̇₂ = −K_e‖e‖² − K_z‖z‖²`
    /// for all positive gains.
    Complete,
}

/// A scenario's `law`: one of the two forms of eq. 13 for a torque-driven
/// robot, or the kinematic law ([`crate::law::kinematic`]) for a velocity base.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(
    feature = "serde",
    derive(serde::Deserialize, serde::Serialize, schemars::JsonSchema)
)]
#[cfg_attr(feature = "serde", serde(rename_all = "kebab-case"))]
pub enum Law {
    /// [`Variant::Paper`].
    Paper,
    /// [`Variant::Complete`].
    Complete,
    /// `(v*, ω*)` of the first backstepping step (control-law.md, "Kinematic law").
    Kinematic,
}

impl Law {
    /// The form of eq. 13, `None` for the kinematic law.
    pub fn variant(self) -> Option<Variant> {
        match self {
            Law::Paper => Some(Variant::Paper),
            Law::Complete => Some(Variant::Complete),
            Law::Kinematic => None,
        }
    }

    /// The scenario's name for it.
    pub fn name(self) -> &'static str {
        match self {
            Law::Paper => "paper",
            Law::Complete => "complete",
            Law::Kinematic => "kinematic",
        }
    }
}

impl From<Variant> for Law {
    fn from(v: Variant) -> Law {
        match v {
            Variant::Paper => Law::Paper,
            Variant::Complete => Law::Complete,
        }
    }
}

/// `L_X, L_Y` and the time derivatives of `L_Y` at one instant.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Offset {
    /// `L_X = L_Xoff + L > 0`, m.
    pub lx: f64,
    /// `L_Y = L_Yoff + L_Ycomp`, m.
    pub ly: f64,
    /// `L̇_Y`, m/s.
    pub dly: f64,
    /// `L̈_Y`, m/s².
    pub ddly: f64,
}

/// What the leader is doing, as the law sees it: `p_d, ṗ_d, p̈_d`.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct LeaderMotion {
    /// `p_d`, m.
    pub p: [f64; 2],
    /// `ṗ_d`, m/s.
    pub dp: [f64; 2],
    /// `p̈_d`, m/s².
    pub ddp: [f64; 2],
}

impl LeaderMotion {
    /// A virtual leader: the reference's `p_d`, `ṗ_d`, `p̈_d` at one instant.
    #[inline]
    pub fn of_jet(jet: &Jet) -> LeaderMotion {
        LeaderMotion {
            p: jet.p,
            dp: jet.dp,
            ddp: jet.ddp,
        }
    }

    /// A leader that is itself a robot in state `s`, accelerating at `dv`
    /// (control-law.md, "Leader velocity and curvature"):
    /// `ṗ_d = v [cos θ, sin θ]`, `p̈_d = v̇ [cos θ, sin θ] + v ω [−sin θ, cos θ]`.
    #[inline]
    pub fn of_robot(s: &State, dv: f64) -> LeaderMotion {
        let (sin, cos) = s.theta.sin_cos();
        let (dp, ddp) = robot_leader(sin, cos, s.v, s.omega, dv);
        LeaderMotion {
            p: [s.x, s.y],
            dp,
            ddp,
        }
    }
}

/// `ṗ_d` and `p̈_d` of a robot leader moving at `v, ω` with heading `(sin, cos)`
/// and accelerating at `dv` ([`LeaderMotion::of_robot`]). `p̈_d` is affine in
/// `dv`; `A` may be a number type that carries that dependence (a chain of
/// followers solves for every `v̇` at once that way).
#[inline(always)]
pub(crate) fn robot_leader<V: Real, A>(sin: V, cos: V, v: V, omega: V, dv: A) -> ([V; 2], [A; 2])
where
    A: Copy + Mul<V, Output = A> + Add<V, Output = A> + Sub<V, Output = A>,
{
    let vw = v * omega;
    (
        [v * cos, v * sin],
        [dv * cos - vw * sin, dv * sin + vw * cos],
    )
}

/// The law's output at one instant.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct LawOutput {
    /// The commanded input `u = [u1, u2]` (before any torque saturation).
    pub u: Input,
    /// Tracking error `e` (eq. 7), follower body frame, m.
    pub e: [f64; 2],
    /// Backstepping error `z` (eq. 10), follower body frame, m/s.
    pub z: [f64; 2],
}

/// `R(θ) a`: a world-frame vector in the robot's body frame.
#[inline(always)]
fn rotate<V: Real>(sin: V, cos: V, a: [V; 2]) -> [V; 2] {
    [cos * a[0] + sin * a[1], -sin * a[0] + cos * a[1]]
}

/// Tracking error `e` (eq. 7) and backstepping error `z` (eq. 10, with `L̇_Y`).
///
/// `(sin, cos)` are those of the heading θ. Generic over dual numbers so that tests
/// can differentiate `e`, `z` and `V₂` along the plant's motion exactly; the law
/// uses the same formulas ([`law`]).
#[inline]
#[allow(clippy::too_many_arguments)]
pub fn errors<D: DualNum<Primitive = f64> + Copy>(
    x: D,
    y: D,
    (sin, cos): (D, D),
    v: D,
    omega: D,
    pd: [D; 2],
    dpd: [D; 2],
    lx: f64,
    ly: D,
    dly: D,
    ke: f64,
) -> ([D; 2], [D; 2]) {
    let body = Body {
        x,
        y,
        sin,
        cos,
        v,
        omega,
    };
    // `1/L_X` and `L̈_Y` do not enter eqs. 7 and 10.
    let hold = Hold {
        lx: D::from(lx),
        inv_lx: D::from(1.0 / lx),
        ly,
        dly,
        ddly: D::from(0.0),
    };
    errors_at(&body, pd, dpd, &hold, D::from(ke))
}

/// The robot constants of eq. 3 as the law uses them, with its ratios
/// precomputed.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct LawRobot {
    /// `m`, kg.
    pub(crate) m: f64,
    /// `J`, kg m².
    pub(crate) j: f64,
    /// `η/m`, 1/s.
    pub(crate) eta_m: f64,
    /// `ψ/J`, 1/s.
    pub(crate) psi_j: f64,
}

impl LawRobot {
    #[inline]
    pub(crate) fn new(r: &RobotParams) -> LawRobot {
        LawRobot {
            m: r.mass(),
            j: r.inertia(),
            eta_m: r.linear_friction() / r.mass(),
            psi_j: r.angular_friction() / r.inertia(),
        }
    }
}

/// A robot's state with its heading as `(sin θ, cos θ)`, in any number type.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Body<V> {
    pub(crate) x: V,
    pub(crate) y: V,
    pub(crate) sin: V,
    pub(crate) cos: V,
    pub(crate) v: V,
    pub(crate) omega: V,
}

impl<V: Copy> Body<V> {
    /// The body of a state `[x, y, θ, v, ω]` whose heading is `(sin, cos)`.
    #[inline(always)]
    pub(crate) fn of(x: &[V; 5], sin: V, cos: V) -> Body<V> {
        Body {
            x: x[0],
            y: x[1],
            sin,
            cos,
            v: x[3],
            omega: x[4],
        }
    }
}

/// Where the follower holds its leader at one instant: `L_X` (and `1/L_X`),
/// `L_Y`, `L̇_Y`, `L̈_Y` ([`Offset`] in any number type).
#[derive(Debug, Clone, Copy)]
pub(crate) struct Hold<V> {
    pub(crate) lx: V,
    pub(crate) inv_lx: V,
    pub(crate) ly: V,
    pub(crate) dly: V,
    pub(crate) ddly: V,
}

impl Hold<f64> {
    /// The offsets `off` as the law holds them (with `1/L_X`).
    #[inline(always)]
    pub(crate) fn of(off: &Offset) -> Hold<f64> {
        Hold {
            lx: off.lx,
            inv_lx: 1.0 / off.lx,
            ly: off.ly,
            dly: off.dly,
            ddly: off.ddly,
        }
    }
}

/// Everything of eqs. 7–13 that comes before the leader's acceleration `p̈_d`
/// enters: `e`, `z`, and `h` without its `−R p̈_d` term.
#[derive(Debug, Clone, Copy)]
pub(crate) struct LawPartial<V> {
    /// `e` (eq. 7).
    pub(crate) e: [V; 2],
    /// `z` (eq. 10).
    pub(crate) z: [V; 2],
    /// `h + R p̈_d` (eq. 12).
    h_pre: [V; 2],
    sin: V,
    cos: V,
    /// `J/L_X` and `L_Y/L_X`, the entries of `B⁻¹` that vary.
    j_lx: V,
    ly_lx: V,
}

/// Eqs. 7, 8, 10 and 12 up to the leader's acceleration, in any number type.
#[inline(always)]
pub(crate) fn law_partial<V: Real>(
    robot: &LawRobot,
    s: &Body<V>,
    pd: [V; 2],
    dpd: [V; 2],
    hold: &Hold<V>,
    ke: V,
) -> LawPartial<V> {
    let Hold {
        lx,
        inv_lx,
        ly,
        dly,
        ddly,
    } = *hold;
    let (v, w) = (s.v, s.omega);
    // eqs. 7 and 10
    let (e, z) = errors_at(s, pd, dpd, hold, ke);
    let rdp = rotate(s.sin, s.cos, dpd);
    // ė (eq. 8, with L̇_Y) = −S e + ξ − R ṗ_d + [0, L̇_Y] = −S e + z − K_e e
    let de = [w * e[1] + z[0] - ke * e[0], -w * e[0] + z[1] - ke * e[1]];
    // eq. 12 without −R p̈_d (S R ṗ_d = [−ω (Rṗ_d)₂, ω (Rṗ_d)₁])
    let h_pre = [
        -w * dly + ly * robot.psi_j * w - v * robot.eta_m - w * rdp[1] + ke * de[0],
        -lx * robot.psi_j * w + w * rdp[0] + ddly + ke * de[1],
    ];
    LawPartial {
        e,
        z,
        h_pre,
        sin: s.sin,
        cos: s.cos,
        j_lx: inv_lx * robot.j,
        ly_lx: ly * inv_lx,
    }
}

/// The rest of eq. 12 and eq. 13: `h = h_pre − R p̈_d`, `w = −h − K_z z (− e)`,
/// `u = B⁻¹ w` with `B⁻¹ = [[m, m L_Y/L_X], [0, J/L_X]]`.
///
/// `u` is affine in `p̈_d`: `A` may be the plain number type or one that
/// carries the dependence on a leader's unknown acceleration.
#[inline(always)]
pub(crate) fn law_finish<V: Real, A>(
    robot: &LawRobot,
    p: &LawPartial<V>,
    ddp: [A; 2],
    kz: V,
    variant: Variant,
) -> [A; 2]
where
    A: Copy
        + Add<Output = A>
        + Add<V, Output = A>
        + Sub<V, Output = A>
        + Mul<V, Output = A>
        + Mul<f64, Output = A>
        + Neg<Output = A>,
{
    // R p̈_d
    let rddp = [
        ddp[0] * p.cos + ddp[1] * p.sin,
        ddp[1] * p.cos + -(ddp[0] * p.sin),
    ];
    let h = [-rddp[0] + p.h_pre[0], -rddp[1] + p.h_pre[1]];
    let mut wv = [-h[0] - kz * p.z[0], -h[1] - kz * p.z[1]];
    if variant == Variant::Complete {
        wv[0] = wv[0] - p.e[0];
        wv[1] = wv[1] - p.e[1];
    }
    // eq. 13: u = B⁻¹ w
    [(wv[0] + wv[1] * p.ly_lx) * robot.m, wv[1] * p.j_lx]
}

/// The leader-follower law, eqs. 7–13 (pure tracking, eqs. 14–16, when
/// `off = [L, 0, 0, 0]`).
#[inline]
pub fn law(
    robot: &RobotParams,
    s: &State,
    leader: &LeaderMotion,
    off: &Offset,
    gains: Gains,
    variant: Variant,
) -> LawOutput {
    let (sin, cos) = s.theta.sin_cos();
    let body = Body {
        x: s.x,
        y: s.y,
        sin,
        cos,
        v: s.v,
        omega: s.omega,
    };
    let hold = Hold::of(off);
    let lr = LawRobot::new(robot);
    let p = law_partial(&lr, &body, leader.p, leader.dp, &hold, gains.ke);
    let [u1, u2] = law_finish(&lr, &p, leader.ddp, gains.kz, variant);
    LawOutput {
        u: Input { u1, u2 },
        e: p.e,
        z: p.z,
    }
}

/// `V₂ = ½‖e‖² + ½‖z‖²`, the second-step Lyapunov function.
#[inline]
pub fn lyapunov(e: [f64; 2], z: [f64; 2]) -> f64 {
    0.5 * (e[0] * e[0] + e[1] * e[1] + z[0] * z[0] + z[1] * z[1])
}

/// What `V̇₂` must equal along the closed loop (control-law.md):
/// `−K_e‖e‖² + eᵀz − K_z‖z‖²` (paper) or `−K_e‖e‖² − K_z‖z‖²` (complete).
#[inline]
pub fn lyapunov_rate(e: [f64; 2], z: [f64; 2], gains: Gains, variant: Variant) -> f64 {
    let ee = e[0] * e[0] + e[1] * e[1];
    let zz = z[0] * z[0] + z[1] * z[1];
    let cross = match variant {
        Variant::Paper => e[0] * z[0] + e[1] * z[1],
        Variant::Complete => 0.0,
    };
    -gains.ke * ee + cross - gains.kz * zz
}

/// Eqs. 7 and 10 in any number type (`f64`, duals, SIMD lanes): `e` and `z`
/// of a body holding its leader at `hold` (`1/L_X` and `L̈_Y` do not enter).
/// The one place of these formulas: [`errors`], [`law`], [`crate::law::kinematic`]
/// and the SIMD kernels all come here.
#[inline(always)]
pub(crate) fn errors_at<V: Real>(
    s: &Body<V>,
    pd: [V; 2],
    dpd: [V; 2],
    hold: &Hold<V>,
    ke: V,
) -> ([V; 2], [V; 2]) {
    let (sin, cos) = (s.sin, s.cos);
    let d = rotate(sin, cos, [s.x - pd[0], s.y - pd[1]]);
    let e = [d[0] + hold.lx, d[1] + hold.ly];
    let rdp = rotate(sin, cos, dpd);
    let xi = [s.v - s.omega * hold.ly, s.omega * hold.lx];
    let z = [
        xi[0] - rdp[0] + e[0] * ke,
        xi[1] - rdp[1] + hold.dly + e[1] * ke,
    ];
    (e, z)
}
