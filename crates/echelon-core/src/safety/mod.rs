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
//! to a speed envelope ([`Envelope`]: no reverse, `|ω|` and `v` bounded; a
//! nominal at the top speed is held to it too), and
//! a robot with a `torque_limit` has its nominal limited first with its turn
//! kept ([`RobotParams::limit`]), so a command that saturates both wheels
//! still steers. Issue 20 found a crossing of two Table I robots that
//! diverged (‖e‖ ≈ 1e213 m) without these.
//!
//! ## Velocity bases with lag: relative degree two
//!
//! A base that follows its command through a lag on either axis
//! (`v̇ = (v* − v)/τ_v`, `ω̇ = (ω* − ω)/τ_ω`, [`VelocityBase`]) is filtered like
//! a torque-driven robot: `p̈_i = f_i + R(θ) diag(1/τ_v, 1/τ_ω) x` with
//! `x = (v*, L ω*)` and `f_i = R(θ)(−v/τ_v − L ω², v ω − L ω/τ_ω)` from the
//! actual speeds in the state, the same exponential barrier, the speed
//! envelope with the base's limits, the base's speed and acceleration limits
//! as hard rows and the same emergency action. The lags are taken as seen
//! over the controller period ([`STEP_LAG`] for a lag-free axis without one).
//! It holds while `(γ + p) τ_v ≤ 1` and `a_max ≥ (γ + p) v_max`
//! (`docs/safety.md`, "Velocity bases with lag").
//!
//! A state or nominal that is not finite is passed on unchanged, for the
//! divergence guard ([`crate::sim::guard`]) to report.
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
//! exactly, by enumerating active sets (`qp.rs`; clarabel beyond
//! [`MAX_ROWS`] rows with the `clarabel` feature). The nominal is
//! first limited by the base ([`VelocityBase::limit`]); if it satisfies every
//! constraint it is returned unchanged (no solve). When the solver reports
//! anything but a solution, or its answer breaks a constraint by more than
//! [`TOLERANCE`], the robot brakes ([`Outcome::Braked`]): a velocity base
//! takes the command that breaks the barriers least (one shared slack)
//! within its speed limits, zero if even that fails (before issue 20's last
//! survey it stopped dead, which left a cooperative neighbour's half of their
//! pair untaken: 1.6 cm inside the radius); a torque-driven robot takes the
//! barriers alone (the envelope given up), else the command that breaks the
//! barriers and the envelope least, within its wheel-torque limits or,
//! without them, an acceleration box (`SafetyFilter::emergency`,
//! [`EMERGENCY_ACCEL`]); `u = (−η v, −ψ ω)` only if no solver answers.
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
//! Each start is counted ([`SafetyFilter::deadlock_breaks`]). A robot moving
//! with a neighbour that sits between it and its slot keeps most of its
//! nominal (the formation's speed) and never counts as stuck: with the law's
//! ‖e‖ ([`SafetyFilter::set_tracking_error`]) the monitor also asks for
//! progress, ‖e‖ down by [`PROGRESS_FRACTION`] within [`PROGRESS_WINDOW`]
//! while the filter acts, or the point moving by that fraction of ‖e‖
//! relative to the neighbour or obstacle nearest it; a robot that moves
//! only along with what holds it starts breaking (or turns further).
//!
//! **Dense encounters** (issue trust2, item 4: 8 to 16 robots swapping
//! across a circle). Waiting [`STUCK_TIME`] let a crowd close into a ring
//! at the radius round the centre, every robot wedged between its two
//! neighbours; a torque robot, which may not reverse, could not leave it.
//! So in an *encounter*, where the nominal closes on a neighbour that comes
//! toward the robot (its point at 1 cm/s or more) faster than their barrier
//! allows, the robot counts as stuck while less than [`ENCOUNTER_SHARE`]
//! (90 %) of its nominal point motion survives, and starts breaking at once:
//! the right-hand rule, applied while there is still room to slide past.
//! Each robot decides from its own state and what it sees of its
//! neighbours; nothing random, the same inputs give the same commands. A
//! robot whose nominal is free, or that only rides beside a neighbour, is
//! untouched; the rows are never relaxed. For a lag-free velocity base the
//! still test reads the filtered command (its motion over the coming
//! period), not the speeds in its state, which a caller may fill with the
//! command it asked for. A break ends when the nominal is free, or when,
//! unturned, it keeps nearly all of its motion ([`ENCOUNTER_SHARE`]: the
//! robot is clear; not in an encounter, nor a break the progress test
//! started).
//!
//! [`RobotParams::limit`]: crate::model::RobotParams::limit
//! [`VelocityBase::limit`]: crate::model::base::VelocityBase::limit
//! [`VelocityBase`]: crate::model::base::VelocityBase

mod config;
mod deadlock;
mod filter;
mod neighbour;
mod qp;
#[cfg(test)]
mod strategies;
mod tally;
mod torque;
mod velocity;

pub use config::SafetyConfig;
pub use deadlock::{
    BIAS_ANGLE, DEADLOCK_MEMORY, ENCOUNTER_SHARE, PROGRESS_FLOOR, PROGRESS_FRACTION,
    PROGRESS_WINDOW, STUCK_TIME,
};
pub use filter::{EMERGENCY_ACCEL, Envelope, Filtered, INNER_RATE, Outcome, SafetyFilter};
pub use neighbour::{
    Neighbour, Obstacle, UNCERTAINTY_SIGMAS, point, start_conflict, uncertainty_margin,
};
pub use qp::{Constraint, MAX_ROWS, TOLERANCE};
pub use tally::Tally;
pub use velocity::STEP_LAG;
