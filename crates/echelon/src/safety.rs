//! Barrier-certificate safety filter (issue 15, `docs/safety.md`): between the
//! formation law and the base, each robot's command is replaced by the closest
//! command that keeps it clear of its neighbours and of known obstacles.
//!
//! ## What is kept apart
//!
//! Every robot `i` has the point `p_i = (x_i, y_i) + L_i (cos θ_i, sin θ_i)`,
//! `L_i` ahead of its axle (the paper's `L`, `[control] l`). `radius` is the
//! **smallest distance between two such points**, and the clearance a point
//! keeps from an obstacle's edge:
//!
//! ```text
//! h_ij = ‖p_i − p_j‖² − radius²                 (another robot j)
//! h_io = ‖p_i − c_o‖² − (r_o + radius)²         (a disc obstacle o: centre c_o, radius r_o)
//! ```
//!
//! The safe set is `h ≥ 0`.
//!
//! ## Velocity bases: `ḣ ≥ −γ h`, linear in `(v, ω)`
//!
//! `ṗ_i = v (cos θ, sin θ) + L ω (−sin θ, cos θ) = R(θ) diag(1, L) (v, ω)ᵀ`, so
//! with `d = p_i − p_j`, `ḣ_ij = 2 dᵀ(ṗ_i − ṗ_j)` is affine in robot i's command.
//! `γ` is `gain` (1/s).
//!
//! **Decentralised responsibility.** A *cooperative* neighbour (one that runs
//! this filter too, [`Neighbour::cooperative`]) takes half of the pair's
//! constraint, reciprocally: with `ṗ_i⁰`, `ṗ_j⁰` the velocities both robots
//! measure now (the same numbers for both),
//!
//! ```text
//! robot i:  2 dᵀ ṗ_i     ≥ −(γ/2) h_ij + dᵀ(ṗ_i⁰ + ṗ_j⁰)
//! robot j:  2 (−d)ᵀ ṗ_j  ≥ −(γ/2) h_ij + (−d)ᵀ(ṗ_i⁰ + ṗ_j⁰)
//! sum:      ḣ_ij = 2 dᵀ(ṗ_i − ṗ_j) ≥ −γ h_ij
//! ```
//!
//! The shared term cancels in the sum whatever its value, so when both robots
//! filter at the same instants from the same measurements the pair satisfies
//! the whole constraint and, by the comparison lemma,
//! `h_ij(t) ≥ h_ij(0) e^{−γ t} ≥ 0`. Each robot's share is half of the change
//! the pair needs from its measured motion (`2 dᵀ(ṗ_i − ṗ_i⁰) ≥ ½(−γ h − ḣ⁰)`),
//! so a follower can keep pace behind a robot that drives away from it; with
//! the shared term set to zero this is the Robotarium's split, which makes a
//! robot that follows another at a distance `ρ` slower than `γ (ρ² − radius²)/(4ρ)`.
//! A neighbour that does not filter is given the whole constraint, using its
//! measured velocity `ṗ_j`: `2 dᵀ ṗ_i ≥ −γ h_ij + 2 dᵀ ṗ_j`. Obstacles do not
//! move: `2 dᵀ ṗ_i ≥ −γ h_io`.
//!
//! ## Torque-driven robots: exponential CBF of relative degree two
//!
//! With eq. 3 (`m v̇ + η v = u1`, `J ω̇ + ψ ω = u2`), `ṗ` does not depend on
//! `u = (u1, u2)` but `p̈` does:
//!
//! ```text
//! p̈_i = f_i + (cos θ, sin θ) u1/m + L (−sin θ, cos θ) u2/J,
//! f_i = (cos θ, sin θ)(−η v/m − L ω²) + (−sin θ, cos θ)(v ω − L ψ ω/J)
//! ḧ_ij = 2‖ṗ_i − ṗ_j‖² + 2 dᵀ(p̈_i − p̈_j)
//! ```
//!
//! The constraint is `ḧ + (γ + p) ḣ + γ p h ≥ 0`, `p = max(γ, `[`INNER_RATE`]`)`:
//! with `ψ₁ = ḣ + γ h` it reads `ψ̇₁ + p ψ₁ ≥ 0`, which keeps `ψ₁ ≥ 0` if it
//! starts so (robots at rest outside the radius) and then `h ≥ 0`. The same
//! split applies (with the shared term zero): toward a cooperative neighbour
//! a robot takes `2 dᵀ p̈_i ≥ −½(2‖Δṗ‖² + (γ + p) ḣ + γ p h)` and leaves
//! `−2 dᵀ p̈_j` to its neighbour; a non-cooperative one's measured `p̈_j`
//! enters.
//!
//! The point `L` ahead has relative degree two, but the heading is its
//! internal dynamics, unstable in reverse; the QP's answer is therefore held
//! to a speed envelope ([`Envelope`]: no reverse, `|ω|` and `v` bounded), and
//! a robot with a `torque_limit` has its nominal limited first with its turn
//! kept ([`RobotParams::limit`]), so a command that saturates both wheels
//! still steers. Issue 20 found a crossing of two Table I robots that
//! diverged (‖e‖ ≈ 1e213 m) without these.
//!
//! ## The quadratic program
//!
//! The QP is solved in the point's units, `x = diag(1, L)(v, ω)` for a
//! velocity base (so `‖x − x₀‖ = ‖ṗ − ṗ₀‖`: the point's velocity changes as
//! little as possible) and `x = (u1/m, L u2/J)` for torques (the point's
//! acceleration changes as little as possible):
//!
//! ```text
//! min ½‖x − x₀‖²   s.t.  a_kᵀ x ≥ b_k (every barrier),  the base's limits
//! ```
//!
//! with `clarabel` (interior point, default tolerances 1e-8). The nominal is
//! first limited by the base ([`VelocityBase::limit`]); if it satisfies every
//! constraint it is returned unchanged (no solve). When the solver reports
//! anything but a solution, or its answer breaks a constraint by more than
//! [`TOLERANCE`], the robot brakes ([`Outcome::Braked`]): a velocity base
//! takes the command that breaks the barriers least (one shared slack)
//! within its speed limits, zero if even that fails (before issue 20's last
//! survey it stopped dead, which left a cooperative neighbour's half of their
//! pair untaken: 1.6 cm inside the radius); for a torque-driven robot with a `torque_limit`, the command
//! that breaks the barriers and the envelope least within its wheel-torque
//! limits (`solve_relaxed`), else `u = (−η v, −ψ ω)` (twice the friction's
//! deceleration).
//!
//! ## Deadlock
//!
//! Two robots meeting head-on in perfect symmetry can stop nose to nose: each
//! QP answer is the nominal projected onto its half-plane, which is zero; two
//! robots that must swap sides while both move forward can likewise slide
//! along side by side. A robot is *stuck* while the filter acts, less than half
//! of the point motion the nominal asks for survives (`x·x₀ < ½‖x₀‖²`) and the
//! nominal asks for at least 1 cm/s (or 1 cm/s²); after
//! [`STUCK_TIME`] stuck it starts *breaking* the deadlock: the desired point
//! velocity (or acceleration) is turned clockwise by [`BIAS_ANGLE`] before the
//! QP (keep right: both robots turn the same way, so they slide past each
//! other), until the unbiased nominal command satisfies every constraint again.
//! Each start is counted ([`SafetyFilter::deadlock_breaks`]).

use clarabel::algebra::CscMatrix;
use clarabel::solver::{DefaultSettings, DefaultSolver, IPSolver, NonnegativeConeT, SolverStatus};

use crate::base::{VelocityBase, VelocityCommand};
use crate::check;
use crate::error::ParamError;
use crate::model::{Input, RobotParams, State};

/// How far (in the QP's units: m²/s for velocity bases, m²/s² for torques)
/// the solver's answer may break a constraint before it is refused.
pub const TOLERANCE: f64 = 1e-6;

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

/// How long after its filter last changed its command a robot still counts
/// as held by it ([`SafetyFilter::deadlocked`]), s.
pub const DEADLOCK_MEMORY: f64 = 10.0;

/// How long a robot must be stuck before it breaks a deadlock, s.
pub const STUCK_TIME: f64 = 1.0;

/// How far the desired point motion is turned clockwise while breaking a
/// deadlock, rad.
pub const BIAS_ANGLE: f64 = std::f64::consts::FRAC_PI_4;

/// The filter's settings for one robot (`[safety]`).
#[derive(Debug, Clone, Copy, PartialEq)]
#[non_exhaustive]
pub struct SafetyConfig {
    /// Smallest distance between two robots' points `L` ahead, and the
    /// clearance a point keeps from an obstacle's edge, m.
    pub radius: f64,
    /// `γ`, 1/s: `ḣ ≥ −γ h` (velocity bases), `ḧ + 2γ ḣ + γ² h ≥ 0` (torques).
    pub gain: f64,
    /// Neighbours whose point is farther than this are ignored, m (may be
    /// infinite).
    pub range: f64,
}

impl SafetyConfig {
    /// Refuses `radius`, `gain` that are not finite and `> 0`, and a `range`
    /// that is not `> radius` (it may be infinite).
    pub fn new(radius: f64, gain: f64, range: f64) -> Result<SafetyConfig, ParamError> {
        check::positive("radius", radius)?;
        check::positive("gain", gain)?;
        check::require(
            "range",
            range,
            range > radius,
            format!("must exceed radius = {radius} m (robots beyond it are not seen)"),
        )?;
        Ok(SafetyConfig {
            radius,
            gain,
            range,
        })
    }
}

/// A static disc obstacle, built through [`Obstacle::new`] (which checks it).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Obstacle {
    x: f64,
    y: f64,
    r: f64,
}

impl Obstacle {
    /// Refuses a centre that is not finite and `r` that is not `> 0`.
    pub fn new(x: f64, y: f64, r: f64) -> Result<Obstacle, ParamError> {
        check::finite("x", x)?;
        check::finite("y", y)?;
        check::positive("r", r)?;
        Ok(Obstacle { x, y, r })
    }

    /// Centre, m.
    #[inline]
    pub const fn x(&self) -> f64 {
        self.x
    }

    /// Centre, m.
    #[inline]
    pub const fn y(&self) -> f64 {
        self.y
    }

    /// Radius, m (`> 0`).
    #[inline]
    pub const fn r(&self) -> f64 {
        self.r
    }
}

/// What a robot knows of a neighbour: its point `L` ahead and that point's
/// motion (from the neighbour's state stream in a fleet, from the state in the
/// simulator).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Neighbour {
    /// `p_j`, m.
    pub p: [f64; 2],
    /// `ṗ_j`, m/s (used only for a non-cooperative neighbour, and for `ḣ` of
    /// the torque constraint).
    pub dp: [f64; 2],
    /// `p̈_j`, m/s² (only for a non-cooperative neighbour of a torque-driven
    /// robot; zero when unknown).
    pub ddp: [f64; 2],
    /// Whether the neighbour runs this filter too and so takes half of each
    /// pair constraint.
    pub cooperative: bool,
}

impl Neighbour {
    /// The neighbour seen from its state `s` and its `L`: `p_j`, and `ṗ_j` from
    /// its velocities `(v, ω)`; `dv = (v̇, ω̇)` gives `p̈_j` (`None`: zero).
    pub fn of_state(s: &State, l: f64, dv: Option<[f64; 2]>, cooperative: bool) -> Neighbour {
        let (sin, cos) = s.theta.sin_cos();
        let dp = [s.v * cos - l * s.omega * sin, s.v * sin + l * s.omega * cos];
        let ddp = dv.map_or([0.0; 2], |[a, alpha]| {
            let along = a - l * s.omega * s.omega;
            let across = s.v * s.omega + l * alpha;
            [along * cos - across * sin, along * sin + across * cos]
        });
        Neighbour {
            p: point(s, l),
            dp,
            ddp,
            cooperative,
        }
    }
}

/// `p = (x, y) + L (cos θ, sin θ)`: the point the filter keeps apart.
#[inline]
pub fn point(s: &State, l: f64) -> [f64; 2] {
    let (sin, cos) = s.theta.sin_cos();
    [s.x + l * cos, s.y + l * sin]
}

/// The first robot (index) whose point `L` ahead starts inside the safe
/// set's complement, and why: within `radius` of another robot's point
/// (`points[i]`, the larger radius of the two robots that filter) or of an
/// obstacle's edge. `configs[i]` is `None` for a robot that does not filter
/// (it is checked only against robots that do).
pub fn start_conflict(
    points: &[[f64; 2]],
    configs: &[Option<SafetyConfig>],
    obstacles: &[Obstacle],
) -> Option<(usize, ParamError)> {
    let radius = |i: usize| configs.get(i).copied().flatten().map(|c| c.radius);
    for (i, p) in points.iter().enumerate() {
        for (j, q) in points.iter().enumerate().take(i) {
            let r = match (radius(i), radius(j)) {
                (None, None) => continue,
                (a, b) => a.unwrap_or(0.0).max(b.unwrap_or(0.0)),
            };
            let d = (p[0] - q[0]).hypot(p[1] - q[1]);
            if d < r {
                return Some((
                    i,
                    ParamError::new(
                        "start",
                        d,
                        format!(
                            "m from agent {}'s point L ahead: closer than the safety radius {r} m",
                            j + 1
                        ),
                    ),
                ));
            }
        }
        let Some(r) = radius(i) else { continue };
        for (k, o) in obstacles.iter().enumerate() {
            let clear = (p[0] - o.x).hypot(p[1] - o.y) - o.r;
            if clear < r {
                return Some((
                    i,
                    ParamError::new(
                        "start",
                        clear,
                        format!(
                            "m from obstacle {}'s edge (its point L ahead): closer than the safety radius {r} m",
                            k + 1
                        ),
                    ),
                ));
            }
        }
    }
    None
}

/// One constraint given to the QP: `a · x ≥ b` in the QP's variables
/// (`x = (v, L ω)` or `x = (u1/m, L u2/J)`, see the module documentation).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Constraint {
    /// Row `a`.
    pub a: [f64; 2],
    /// Bound `b`.
    pub b: f64,
}

impl Constraint {
    /// How far `x` satisfies it: `a · x − b` (negative: broken).
    #[inline]
    pub fn slack(&self, x: [f64; 2]) -> f64 {
        self.a[0] * x[0] + self.a[1] * x[1] - self.b
    }
}

/// What the filter did to a command.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Outcome {
    /// The (limited) nominal command satisfied every constraint: unchanged.
    #[default]
    Nominal,
    /// Replaced by the QP's answer.
    Filtered,
    /// The QP was infeasible or the solver failed: the least violation
    /// within the actuator limits, or a brake.
    Braked,
}

/// The filter's answer for one robot at one instant.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Filtered<C> {
    /// The command to send to the base.
    pub command: C,
    /// The law's command, as given.
    pub nominal: C,
    /// What the filter did.
    pub outcome: Outcome,
    /// Whether the robot is breaking a deadlock (its nominal was turned).
    pub deadlock: bool,
    /// Smallest distance from this robot's point to a neighbour's point
    /// within range, m (infinite: none).
    pub min_distance: f64,
}

impl<C> Filtered<C> {
    /// Whether the command differs from the nominal one.
    pub fn active(&self) -> bool {
        self.outcome != Outcome::Nominal
    }
}

/// Deadlock monitor state.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
struct Deadlock {
    stuck_since: Option<f64>,
    breaking: bool,
    breaks: u64,
    /// The last time (s) the filter changed the command (stuck and breaking
    /// a deadlock only happen then).
    last: Option<f64>,
    /// The time of the last call.
    now: f64,
}

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

/// One robot's safety filter: its settings, the QP's buffers and the deadlock
/// monitor. Call [`velocity`](SafetyFilter::velocity) or
/// [`torque`](SafetyFilter::torque) once per controller period with the
/// neighbours the robot knows of (any number; those beyond `range` are
/// ignored) and the known obstacles.
#[derive(Debug, Clone)]
pub struct SafetyFilter {
    config: SafetyConfig,
    rows: Vec<Constraint>,
    deadlock: Deadlock,
    /// How long each command is held, s (0: continuous).
    period: f64,
}

/// The robot's own geometry at one instant.
#[derive(Debug, Clone, Copy)]
struct Own {
    p: [f64; 2],
    dp: [f64; 2],
    cos: f64,
    sin: f64,
}

impl SafetyFilter {
    /// A filter with `config` (valid by [`SafetyConfig::new`]).
    pub fn new(config: SafetyConfig) -> SafetyFilter {
        SafetyFilter {
            config,
            rows: Vec::with_capacity(16),
            deadlock: Deadlock::default(),
            period: 0.0,
        }
    }

    /// The same filter for commands held `period` seconds (the controller's
    /// period): a velocity base's barrier rows then use the heading half a
    /// period ahead at the current turn rate. A command `(v, ω)` held for
    /// `T` from heading `θ` moves the point on average along
    /// `R(θ + ωT/2) (v, Lω) sinc(ωT/2)`, not `R(θ) (v, Lω)`; with a 10 ms
    /// period at 4 rad/s the difference let two points come 1–2 mm inside
    /// the radius (issue 20's survey).
    pub fn with_period(self, period: f64) -> SafetyFilter {
        SafetyFilter {
            period: if period.is_finite() && period > 0.0 {
                period
            } else {
                0.0
            },
            ..self
        }
    }

    /// Its settings.
    pub fn config(&self) -> &SafetyConfig {
        &self.config
    }

    /// The constraints given to the last QP (barriers, then limits), in the
    /// QP's variables.
    pub fn constraints(&self) -> &[Constraint] {
        &self.rows
    }

    /// Whether the filter holds the robot: it changed the command (and so
    /// may be stuck or breaking a deadlock) at its last call or at any call
    /// within [`DEADLOCK_MEMORY`] before it (a robot that keeps falling back
    /// into the same stand-off between breaks, or rides along a neighbour's
    /// barrier beside its slot, is held too).
    pub fn deadlocked(&self) -> bool {
        let d = &self.deadlock;
        d.last.is_some_and(|t| d.now - t <= DEADLOCK_MEMORY)
    }

    /// How many deadlocks it has started breaking.
    pub fn deadlock_breaks(&self) -> u64 {
        self.deadlock.breaks
    }

    /// Filters a velocity base's command `nominal` at time `t` (s) for a robot
    /// in state `me` (its point `l` ahead): `ḣ ≥ −γ h` for every neighbour in
    /// range and every obstacle, and the base's speed limits.
    #[allow(clippy::too_many_arguments)]
    pub fn velocity(
        &mut self,
        t: f64,
        me: &State,
        l: f64,
        nominal: VelocityCommand,
        base: &VelocityBase,
        neighbours: &[Neighbour],
        obstacles: &[Obstacle],
    ) -> Filtered<VelocityCommand> {
        let own = Own::ahead(me, l, 0.5 * self.period);
        let limited = base.limit(nominal).0;
        let x0 = [limited.v, l * limited.omega];
        let gamma = self.config.gain;
        self.rows.clear();
        let min_distance = self.barriers(&own, neighbours, obstacles, |d, h, n| {
            let a = own.row(d);
            let b = match n {
                Some(n) if n.cooperative => {
                    let shared = [own.dp[0] + n.dp[0], own.dp[1] + n.dp[1]];
                    -0.5 * gamma * h + d[0] * shared[0] + d[1] * shared[1]
                }
                Some(n) => -gamma * h + 2.0 * (d[0] * n.dp[0] + d[1] * n.dp[1]),
                None => -gamma * h,
            };
            Constraint { a, b }
        });
        let barriers = self.rows.len();
        push_box(&mut self.rows, [base.v_max(), l * base.omega_max()]);
        let (x, outcome, deadlock) = self.decide(t, x0, barriers, [0.0, 0.0]);
        let command = match outcome {
            Outcome::Nominal => limited,
            // No command satisfies every barrier within the box: the one
            // that breaks them least (one shared slack) within the base's
            // limits, so its neighbours' shares are missed as little as
            // possible; zero if even that fails.
            Outcome::Braked => {
                solve_relaxed(&self.rows, barriers, x0).map_or(VelocityCommand::default(), |x| {
                    VelocityCommand {
                        v: x[0],
                        omega: x[1] / l,
                    }
                })
            }
            Outcome::Filtered => VelocityCommand {
                v: x[0],
                omega: x[1] / l,
            },
        };
        Filtered {
            command,
            nominal,
            outcome,
            deadlock,
            min_distance,
        }
    }

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
        let limited = robot.limit(nominal).0;
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
        let (x, outcome, deadlock) = self.decide(t, x0, barriers, f);
        let command = match outcome {
            Outcome::Nominal => limited,
            // No command satisfies every row. With wheel-torque limits:
            // the command that breaks the barriers and the envelope least
            // within them (the brake is the torque the robot has, not a
            // fixed law). Without (the relaxed answer would be unbounded):
            // friction's brake.
            Outcome::Braked => match robot.torque_limit().and_then(|_| {
                // The barriers within the wheel limits, the envelope given up
                // first; else the least violation of both.
                let mut keep: Vec<Constraint> = self.rows[..barriers].to_vec();
                keep.extend_from_slice(&self.rows[soft_end..]);
                solve(&keep, x0).or_else(|| solve_relaxed(&self.rows, soft_end, x0))
            }) {
                Some(x) => Input {
                    u1: m * x[0],
                    u2: j * x[1] / l,
                },
                None => robot.brake(me),
            },
            Outcome::Filtered => Input {
                u1: m * x[0],
                u2: j * x[1] / l,
            },
        };
        Filtered {
            command,
            nominal,
            outcome,
            deadlock,
            min_distance,
        }
    }

    /// Pushes one barrier row per neighbour in range and per obstacle, made
    /// by `row(d, h, neighbour)`; returns the smallest distance to a
    /// neighbour's point in range.
    fn barriers(
        &mut self,
        own: &Own,
        neighbours: &[Neighbour],
        obstacles: &[Obstacle],
        row: impl Fn([f64; 2], f64, Option<&Neighbour>) -> Constraint,
    ) -> f64 {
        let SafetyConfig { radius, range, .. } = self.config;
        let mut min_distance = f64::INFINITY;
        for n in neighbours {
            let d = [own.p[0] - n.p[0], own.p[1] - n.p[1]];
            let dist = d[0].hypot(d[1]);
            if dist > range {
                continue;
            }
            min_distance = min_distance.min(dist);
            let h = d[0] * d[0] + d[1] * d[1] - radius * radius;
            self.rows.push(row(d, h, Some(n)));
        }
        for o in obstacles {
            let d = [own.p[0] - o.x, own.p[1] - o.y];
            let clear = o.r + radius;
            let h = d[0] * d[0] + d[1] * d[1] - clear * clear;
            self.rows.push(row(d, h, None));
        }
        min_distance
    }

    /// The QP's answer for the desired `x0` and the rows gathered, the
    /// outcome and whether a deadlock is being broken; updates the monitor.
    /// `drift` is the part of the point's motion the command does not set
    /// (zero for velocity bases), for the stuck test.
    fn decide(
        &mut self,
        t: f64,
        x0: [f64; 2],
        barriers: usize,
        drift: [f64; 2],
    ) -> ([f64; 2], Outcome, bool) {
        let satisfied = |rows: &[Constraint], x: [f64; 2]| rows.iter().all(|c| c.slack(x) >= 0.0);
        self.deadlock.now = t;
        if satisfied(&self.rows[..barriers], x0) {
            self.deadlock.stuck_since = None;
            self.deadlock.breaking = false;
            return (x0, Outcome::Nominal, false);
        }
        let breaking = self.deadlock.breaking;
        let want = if breaking { turn_right(x0) } else { x0 };
        let (x, outcome) = match solve(&self.rows, want) {
            Some(x) => (x, Outcome::Filtered),
            None => ([0.0; 2], Outcome::Braked),
        };
        // Stuck: less than half of the motion the nominal asks for survives
        // (the point stops, or slides alongside a neighbour it should pass).
        let moved = [x[0] + drift[0], x[1] + drift[1]];
        let asked = [x0[0] + drift[0], x0[1] + drift[1]];
        let asked_sq = asked[0] * asked[0] + asked[1] * asked[1];
        let stuck = asked_sq >= 1e-4 && moved[0] * asked[0] + moved[1] * asked[1] < 0.5 * asked_sq;
        if stuck {
            let since = *self.deadlock.stuck_since.get_or_insert(t);
            if !self.deadlock.breaking && t - since >= STUCK_TIME {
                self.deadlock.breaking = true;
                self.deadlock.breaks += 1;
            }
        } else {
            self.deadlock.stuck_since = None;
        }
        self.deadlock.last = Some(t);
        (x, outcome, breaking)
    }
}

impl Own {
    /// The geometry of `me`, its rows turned to the heading `ahead` seconds
    /// on at its turn rate (0: now).
    fn ahead(me: &State, l: f64, ahead: f64) -> Own {
        let (sin, cos) = (me.theta + me.omega * ahead).sin_cos();
        let Neighbour { p, dp, .. } = Neighbour::of_state(me, l, None, true);
        Own { p, dp, cos, sin }
    }

    /// `2 dᵀ R(θ) x = a · x`: `a = 2 R(θ)ᵀ d` (the point moves at `R(θ) x`).
    fn row(&self, d: [f64; 2]) -> [f64; 2] {
        [
            2.0 * (d[0] * self.cos + d[1] * self.sin),
            2.0 * (-d[0] * self.sin + d[1] * self.cos),
        ]
    }
}

/// `argmin ½‖x − want‖² + ½ W s²` s.t. `a_k·x + s ≥ b_k` for the rows before
/// `soft_end` (one shared slack `s ≥ 0`, `W` = 10⁶) and `a_k·x ≥ b_k` for the
/// rest: the command that breaks the soft rows least, within the hard ones.
/// `None` when even the hard rows cannot be met or the solver fails.
fn solve_relaxed(rows: &[Constraint], soft_end: usize, want: [f64; 2]) -> Option<[f64; 2]> {
    const W: f64 = 1e6;
    let m = rows.len() + 1;
    let p = CscMatrix::new(3, 3, vec![0, 1, 2, 3], vec![0, 1, 2], vec![1.0, 1.0, W]);
    let q = [-want[0], -want[1], 0.0];
    // Columns x₁, x₂, s; rows: −a·x − s ≤ −b (soft), −a·x ≤ −b (hard), −s ≤ 0.
    let mut colptr = vec![0, rows.len(), 2 * rows.len()];
    let mut rowval: Vec<usize> = (0..rows.len()).chain(0..rows.len()).collect();
    let mut nz: Vec<f64> = rows.iter().map(|c| -c.a[0]).collect();
    nz.extend(rows.iter().map(|c| -c.a[1]));
    rowval.extend(0..soft_end);
    nz.extend(std::iter::repeat_n(-1.0, soft_end));
    rowval.push(rows.len());
    nz.push(-1.0);
    colptr.push(nz.len());
    let a = CscMatrix::new(m, 3, colptr, rowval, nz);
    let mut b: Vec<f64> = rows.iter().map(|c| -c.b).collect();
    b.push(0.0);
    let x = clarabel_solve(&p, &q, &a, &b)?;
    let hard_ok = rows[soft_end..]
        .iter()
        .all(|c| c.slack(x) >= -TOLERANCE * (1.0 + c.b.abs()));
    (x.iter().all(|v| v.is_finite()) && hard_ok).then_some(x)
}

/// `|x_k| ≤ bound_k` as four rows (an infinite bound adds none).
fn push_box(rows: &mut Vec<Constraint>, bound: [f64; 2]) {
    for (k, b) in bound.into_iter().enumerate() {
        if b.is_finite() {
            let mut a = [0.0; 2];
            a[k] = 1.0;
            rows.push(Constraint { a, b: -b });
            a[k] = -1.0;
            rows.push(Constraint { a, b: -b });
        }
    }
}

/// `x` turned clockwise by [`BIAS_ANGLE`] (the body frame and the world frame
/// turn together).
fn turn_right(x: [f64; 2]) -> [f64; 2] {
    let (s, c) = BIAS_ANGLE.sin_cos();
    [c * x[0] + s * x[1], -s * x[0] + c * x[1]]
}

/// `argmin ½‖x − want‖²` s.t. every row, by clarabel; `None` when it finds no
/// solution or its answer breaks a row by more than [`TOLERANCE`].
///
/// clarabel builds its solver (and so allocates) on every call; the filter
/// calls it only when the nominal command breaks a constraint.
fn solve(rows: &[Constraint], want: [f64; 2]) -> Option<[f64; 2]> {
    let m = rows.len();
    let p = CscMatrix::new(2, 2, vec![0, 1, 2], vec![0, 1], vec![1.0, 1.0]);
    let q = [-want[0], -want[1]];
    // clarabel's form: A x + s = b, s ≥ 0, i.e. −a·x ≤ −b.
    let mut nz = Vec::with_capacity(2 * m);
    nz.extend(rows.iter().map(|c| -c.a[0]));
    nz.extend(rows.iter().map(|c| -c.a[1]));
    let rowval: Vec<usize> = (0..m).chain(0..m).collect();
    let a = CscMatrix::new(m, 2, vec![0, m, 2 * m], rowval, nz);
    let b: Vec<f64> = rows.iter().map(|c| -c.b).collect();
    let x = clarabel_solve(&p, &q, &a, &b)?;
    (x.iter().all(|v| v.is_finite()) && rows.iter().all(|c| c.slack(x) >= -TOLERANCE)).then_some(x)
}

/// `argmin ½zᵀPz + qᵀz` s.t. `A z ≤ b` by clarabel (default tolerances, quiet):
/// the first two components of `z`, `None` unless solved.
fn clarabel_solve(
    p: &CscMatrix<f64>,
    q: &[f64],
    a: &CscMatrix<f64>,
    b: &[f64],
) -> Option<[f64; 2]> {
    let settings = DefaultSettings {
        verbose: false,
        ..DefaultSettings::default()
    };
    let cones = [NonnegativeConeT(b.len())];
    let mut solver = DefaultSolver::new(p, q, a, b, &cones, settings).ok()?;
    solver.solve();
    match solver.solution.status {
        SolverStatus::Solved | SolverStatus::AlmostSolved => {
            Some([solver.solution.x[0], solver.solution.x[1]])
        }
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use super::*;

    fn config() -> SafetyConfig {
        SafetyConfig::new(0.3, 1.0, 2.0).unwrap()
    }

    fn ideal() -> VelocityBase {
        VelocityBase::new(0.0, 0.0, 0.5, 4.0, f64::INFINITY, f64::INFINITY).unwrap()
    }

    #[test]
    fn a_nominal_that_is_safe_passes_unchanged() {
        let mut f = SafetyFilter::new(config());
        let me = State::at_rest(0.0, 0.0, 0.0);
        // Driving away from a neighbour behind.
        let n = Neighbour::of_state(&State::at_rest(-1.0, 0.0, 0.0), 0.05, None, true);
        let nominal = VelocityCommand { v: 0.3, omega: 0.1 };
        let out = f.velocity(0.0, &me, 0.05, nominal, &ideal(), &[n], &[]);
        assert_eq!(out.outcome, Outcome::Nominal);
        assert_eq!(out.command, nominal);
    }

    #[test]
    fn head_on_the_filter_keeps_half_the_barrier() {
        let mut f = SafetyFilter::new(config());
        let l = 0.05;
        let me = State::at_rest(0.0, 0.0, 0.0);
        let other = State::at_rest(0.6, 0.0, std::f64::consts::PI);
        let n = Neighbour::of_state(&other, l, None, true);
        let out = f.velocity(
            0.0,
            &me,
            l,
            VelocityCommand { v: 0.5, omega: 0.0 },
            &ideal(),
            &[n],
            &[],
        );
        assert_eq!(out.outcome, Outcome::Filtered);
        // d = p_i − p_j = (−0.5, 0), h = 0.25 − 0.09; 2 dᵀṗ = −v ≥ −h/2.
        let h = 0.25 - 0.09;
        assert!((out.command.v - h / 2.0).abs() < 1e-6, "{out:?}");
        assert!(out.command.omega.abs() < 1e-6);
        assert!((out.min_distance - 0.5).abs() < 1e-12);
    }

    #[test]
    fn boxed_in_it_flees_as_fast_as_its_base_allows() {
        // A non-cooperative neighbour rushing in faster than the base can flee.
        let mut f = SafetyFilter::new(config());
        let l = 0.05;
        let me = State::at_rest(0.0, 0.0, 0.0);
        let mut other = State::at_rest(0.40, 0.0, std::f64::consts::PI);
        other.v = 3.0;
        let n = Neighbour::of_state(&other, l, None, false);
        let out = f.velocity(
            0.0,
            &me,
            l,
            VelocityCommand { v: 0.1, omega: 0.0 },
            &ideal(),
            &[n],
            &[],
        );
        assert_eq!(out.outcome, Outcome::Braked);
        // The least violation within |v| ≤ 0.5: full speed straight back.
        assert!((out.command.v + 0.5).abs() < 1e-6, "{out:?}");
        assert!(out.command.omega.abs() < 1e-4, "{out:?}");
    }

    #[test]
    fn bad_settings_are_refused() {
        assert_eq!(
            SafetyConfig::new(0.0, 1.0, 1.0).unwrap_err().field,
            "radius"
        );
        assert_eq!(SafetyConfig::new(0.2, -1.0, 1.0).unwrap_err().field, "gain");
        assert_eq!(SafetyConfig::new(0.2, 1.0, 0.1).unwrap_err().field, "range");
        assert!(SafetyConfig::new(0.2, 1.0, f64::INFINITY).is_ok());
        assert_eq!(Obstacle::new(0.0, 0.0, 0.0).unwrap_err().field, "r");
    }

    mod properties {
        use super::*;
        use proptest::prelude::*;

        fn state() -> impl Strategy<Value = State> {
            (
                -2.0..2.0f64,
                -2.0..2.0f64,
                -3.2..3.2f64,
                -0.5..0.5f64,
                -2.0..2.0f64,
            )
                .prop_map(|(x, y, theta, v, omega)| State {
                    x,
                    y,
                    theta,
                    v,
                    omega,
                })
        }

        fn neighbours() -> impl Strategy<Value = Vec<Neighbour>> {
            prop::collection::vec((state(), any::<bool>()), 0..6).prop_map(|v| {
                v.into_iter()
                    .map(|(s, coop)| Neighbour::of_state(&s, 0.05, Some([0.3, -0.2]), coop))
                    .collect()
            })
        }

        /// Drops neighbours whose point is inside the radius (`h < 0`: the
        /// filter starts outside the unsafe set).
        fn outside(me: &State, l: f64, ns: Vec<Neighbour>, radius: f64) -> Vec<Neighbour> {
            let p = point(me, l);
            ns.into_iter()
                .filter(|n| (p[0] - n.p[0]).hypot(p[1] - n.p[1]) > radius)
                .collect()
        }

        /// `x` of the QP for a velocity command.
        fn x_of(c: VelocityCommand, l: f64) -> [f64; 2] {
            [c.v, l * c.omega]
        }

        proptest! {
            /// The filtered command satisfies every constraint given to the
            /// QP (within [`TOLERANCE`], clarabel's default tolerances 1e-8),
            /// or the robot brakes; a nominal that satisfies them all comes
            /// back bit for bit.
            #[test]
            fn velocity_filter_satisfies_its_constraints(
                me in state(),
                ns in neighbours(),
                v in -0.8..0.8f64,
                omega in -3.0..3.0f64,
                gain in 0.2..5.0f64,
            ) {
                let l = 0.05;
                let config = SafetyConfig::new(0.3, gain, 1.5).unwrap();
                let ns = outside(&me, l, ns, 0.3);
                let obstacles = [Obstacle::new(1.5, -1.5, 0.2).unwrap()];
                let mut f = SafetyFilter::new(config);
                let base = ideal();
                let nominal = VelocityCommand { v, omega };
                let out = f.velocity(0.0, &me, l, nominal, &base, &ns, &obstacles);
                let limited = base.limit(nominal).0;
                let rows = f.constraints().to_vec();
                let nominal_ok = rows.iter().all(|c| c.slack(x_of(limited, l)) >= 0.0);
                match out.outcome {
                    Outcome::Nominal => {
                        prop_assert!(nominal_ok);
                        prop_assert_eq!(out.command, limited);
                    }
                    Outcome::Filtered => {
                        prop_assert!(!nominal_ok);
                        let x = x_of(out.command, l);
                        for c in &rows {
                            prop_assert!(c.slack(x) >= -TOLERANCE, "{c:?} at {x:?}");
                        }
                    }
                    Outcome::Braked => {
                        // Within the base's limits, and breaking the
                        // barriers no more than standing still would.
                        let x = x_of(out.command, l);
                        // (clarabel's tolerance, in x = (v, L ω))
                        prop_assert!(out.command.v.abs() <= base.v_max() + TOLERANCE);
                        prop_assert!(l * out.command.omega.abs() <= l * base.omega_max() + TOLERANCE);
                        let worst = |x: [f64; 2]| {
                            rows.iter().map(|c| -c.slack(x)).fold(0.0f64, f64::max)
                        };
                        prop_assert!(worst(x) <= worst([0.0; 2]) + 1e-6, "{x:?}");
                    }
                }
                if nominal_ok {
                    prop_assert_eq!(out.outcome, Outcome::Nominal);
                }
            }

            /// The same for the torque filter's exponential barriers and the
            /// wheel torque limit.
            #[test]
            fn torque_filter_satisfies_its_constraints(
                me in state(),
                ns in neighbours(),
                u1 in -60.0..60.0f64,
                u2 in -10.0..10.0f64,
                gain in 0.2..5.0f64,
            ) {
                let l = 0.05;
                let robot = RobotParams::AGENT1.with_torque_limit(Some(3.0)).unwrap();
                let config = SafetyConfig::new(0.3, gain, 1.5).unwrap();
                let ns = outside(&me, l, ns, 0.3);
                let mut f = SafetyFilter::new(config);
                let nominal = Input { u1, u2 };
                let out = f.torque(0.0, &me, l, &robot, nominal, &ns, &[]);
                let rows = f.constraints().to_vec();
                let x_of = |u: Input| [u.u1 / robot.mass(), l * u.u2 / robot.inertia()];
                // Barriers, then the speed envelope (4 rows), then the torque limit (4).
                let barriers = rows.len() - 8;
                // The nominal is first limited with its turn kept.
                let limited = robot.limit(nominal).0;
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
        }
    }
}
