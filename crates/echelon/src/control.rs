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
//! Pure tracking is the same law with `L_X = L`, `L_Y = 0` ([`crate::lycomp::Placement::tracking`]).

use num_dual::DualNum;

use crate::model::{Input, RobotParams, State};

/// The backstepping gains.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Gains {
    /// `K_e > 0`: convergence rate of `e` (first step).
    pub ke: f64,
    /// `K_z > 0`: convergence rate of `z` (second step).
    pub kz: f64,
}

impl Gains {
    /// The paper's gains: `K_e = 1.5`, `K_z = 10`.
    pub const PAPER: Gains = Gains { ke: 1.5, kz: 10.0 };
}

/// Which form of eq. 13.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Variant {
    /// The paper's `u = B⁻¹(−h − K_z z)`: leaves the cross term `eᵀz` in `V̇₂`, so
    /// Theorem 1 needs `K_e K_z > 1/4`.
    #[default]
    Paper,
    /// Textbook backstepping `u = B⁻¹(−h − K_z z − e)`: `V̇₂ = −K_e‖e‖² − K_z‖z‖²`
    /// for all positive gains.
    Complete,
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
    /// A leader that is itself a robot in state `s`, accelerating at `dv`
    /// (control-law.md, "Leader velocity and curvature"):
    /// `ṗ_d = v [cos θ, sin θ]`, `p̈_d = v̇ [cos θ, sin θ] + v ω [−sin θ, cos θ]`.
    #[inline]
    pub fn of_robot(s: &State, dv: f64) -> LeaderMotion {
        let (sin, cos) = s.theta.sin_cos();
        LeaderMotion {
            p: [s.x, s.y],
            dp: [s.v * cos, s.v * sin],
            ddp: [
                dv * cos - s.v * s.omega * sin,
                dv * sin + s.v * s.omega * cos,
            ],
        }
    }
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
#[inline]
fn rotate<D: DualNum<Primitive = f64> + Copy>(sin: D, cos: D, a: [D; 2]) -> [D; 2] {
    [cos * a[0] + sin * a[1], -sin * a[0] + cos * a[1]]
}

/// Tracking error `e` (eq. 7) and backstepping error `z` (eq. 10, with `L̇_Y`).
///
/// `(sin, cos)` are those of the heading θ. Generic over dual numbers so that tests
/// can differentiate `e`, `z` and `V₂` along the plant's motion exactly; the law
/// uses it with `f64`.
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
    let d = rotate(sin, cos, [x - pd[0], y - pd[1]]);
    let e = [d[0] + lx, d[1] + ly];
    let rdp = rotate(sin, cos, dpd);
    let xi = [v - omega * ly, omega * lx];
    let z = [xi[0] - rdp[0] + e[0] * ke, xi[1] - rdp[1] + dly + e[1] * ke];
    (e, z)
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
    let (m, j) = (robot.mass, robot.inertia);
    let (eta, psi) = (robot.linear_friction, robot.angular_friction);
    let Offset { lx, ly, dly, ddly } = *off;
    let Gains { ke, kz } = gains;
    let (v, w) = (s.v, s.omega);

    let (sin, cos) = s.theta.sin_cos();
    // eqs. 7 and 10
    let (e, z) = errors(
        s.x,
        s.y,
        (sin, cos),
        v,
        w,
        leader.p,
        leader.dp,
        lx,
        ly,
        dly,
        ke,
    );
    let rdp = rotate(sin, cos, leader.dp);
    let rddp = rotate(sin, cos, leader.ddp);
    // ė (eq. 8, with L̇_Y) = −S e + ξ − R ṗ_d + [0, L̇_Y] = −S e + z − K_e e
    let de = [w * e[1] + z[0] - ke * e[0], -w * e[0] + z[1] - ke * e[1]];
    // eq. 12 (S R ṗ_d = [−ω (Rṗ_d)₂, ω (Rṗ_d)₁])
    let h = [
        -w * dly + (ly / j) * psi * w - (eta / m) * v - w * rdp[1] - rddp[0] + ke * de[0],
        -(lx / j) * psi * w + w * rdp[0] - rddp[1] + ddly + ke * de[1],
    ];
    // eq. 13: u = B⁻¹ w
    let mut wv = [-h[0] - kz * z[0], -h[1] - kz * z[1]];
    if variant == Variant::Complete {
        wv[0] -= e[0];
        wv[1] -= e[1];
    }
    let u2 = (j / lx) * wv[1];
    let u1 = m * (wv[0] + (ly / lx) * wv[1]);
    LawOutput {
        u: Input { u1, u2 },
        e,
        z,
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
