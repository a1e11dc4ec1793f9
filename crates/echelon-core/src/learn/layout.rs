//! What a robot's observation holds, in order (`obs_dim = 10 + 3 K + 4 M`
//! values, `K` the listed neighbours, `M` the listed obstacles), SI units,
//! the robot's body frame (`x` ahead, `y` left):
//!
//! | index | value |
//! |---|---|
//! | 0, 1 | `e` (eq. 7), m: the tracking error of its slot |
//! | 2, 3 | `v`, m/s, and `ω`, rad/s: its own velocities |
//! | 4, 5 | `R ṗ_d`, m/s: its leader's velocity in its frame |
//! | 6, 7 | `R p̈_d`, m/s²: its leader's acceleration in its frame |
//! | 8, 9 | `L_X`, `L_Y`, m: where it holds its leader (eq. 7's offsets) |
//! | 10 + 3k, 11 + 3k | neighbour `k`'s point (`L` ahead) relative to its own point, m |
//! | 12 + 3k | 1 if neighbour `k` is listed, 0 for padding |
//! | 10 + 3K + 4m, 11 + 3K + 4m | obstacle `m`'s centre relative to the robot's point, m |
//! | 12 + 3K + 4m | its radius, m |
//! | 13 + 3K + 4m | 1 if obstacle `m` is listed, 0 for padding |
//!
//! Neighbours are listed nearest first, those within `sense` metres only;
//! obstacles nearest edge first, those whose edge is within `sense` metres
//! only; the rest of the `K` (`M`) entries are zeros.

use crate::model::base::{VelocityBase, VelocityBaseSpec};

/// Index of `e_x` (then `e_y`).
pub const E: usize = 0;
/// Index of `v` (then `ω`).
pub const SPEEDS: usize = 2;
/// Index of `(R ṗ_d)_x` (then `_y`).
pub const LEADER_VELOCITY: usize = 4;
/// Index of `(R p̈_d)_x` (then `_y`).
pub const LEADER_ACCELERATION: usize = 6;
/// Index of `L_X` (then `L_Y`).
pub const OFFSETS: usize = 8;
/// Index of the first neighbour's `dx` (then `dy`, `listed`; 3 values each).
pub const NEIGHBOURS: usize = 10;

/// Values per listed neighbour.
pub const PER_NEIGHBOUR: usize = 3;
/// Values per listed obstacle.
pub const PER_OBSTACLE: usize = 4;

/// Index of the first obstacle's `dx` (then `dy`, `r`, `listed`) with `k`
/// neighbours listed.
pub const fn obstacles(k: usize) -> usize {
    NEIGHBOURS + PER_NEIGHBOUR * k
}

/// Values per observation with `k` neighbours and `m` obstacles listed.
pub const fn obs_dim(k: usize, m: usize) -> usize {
    obstacles(k) + PER_OBSTACLE * m
}

/// The environments' default base: no lag, 0.5 m/s, 2 rad/s (a small
/// research robot's limits).
pub fn default_base() -> VelocityBase {
    VelocityBase::new(VelocityBaseSpec {
        v_max: 0.5,
        omega_max: 2.0,
        ..VelocityBase::IDEAL.spec()
    })
    .unwrap_or_else(|_| unreachable!("finite positive limits"))
}
