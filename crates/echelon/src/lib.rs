//! # echelon
//!
//! Leader-follower formation control of differential-drive robots, after
//! *Leader-Follower Control with Odometry Error Analysis* (the paper), with the
//! corrections of `docs/control-law.md`.
//!
//! The kernel (models, laws, references, formations, the simulator, the
//! safety filter, the batch engine, odometry error models) is
//! [`echelon_core`], re-exported here module by module so that
//! `echelon::control`, `echelon::model`, … name the same items. This crate
//! adds what sits above the kernel:
//!
//! - [`scenario`]: the TOML scenario format, its schema, checks and
//!   plausible ranges, and the paper's built-in setups;
//! - [`output`], [`csv`], [`sample`]: `trajectory.csv` and `summary.json`;
//! - [`stats`]: run statistics (per agent, safety, divergence);
//! - [`odometry`]: the kernel's odometry and the studies above it, Theorem 2
//!   ([`odometry::bound`]) and UMBmark ([`odometry::umbmark`]);
//! - [`sweep`]: Monte Carlo sweeps over odometry errors and fix intervals;
//! - [`identify`]: a robot's eq. 3 parameters or velocity-base lags from its logs;
//! - [`lm`]: Levenberg–Marquardt for the small least-squares fits.
//!
//! Units are SI and angles radians throughout (ROS REP 103).

#![cfg_attr(not(test), warn(clippy::too_many_lines))]

pub use echelon_core::{check, engine, formation, law, learn, math, model, reference, safety, sim};
// The kernel's modules under their own names here too (`echelon::control` is
// `echelon_core::law::control`): what users of `echelon` have always written.
pub use echelon_core::formation::{agent, follow};
pub use echelon_core::law::{control, kinematic, lycomp};
pub use echelon_core::math::{lanes, rng};
pub use echelon_core::model::base;
pub use echelon_core::sim::{guard, plan};

pub mod csv;
pub mod encounter;
pub mod error;
pub mod identify;
pub mod lm;
pub mod odometry;
pub mod output;
pub mod sample;
pub mod scenario;
pub mod stats;
pub mod sweep;

pub use agent::{AgentSpec, Command};
pub use control::{Gains, Variant};
pub use error::{FormationError, OutputError, ParamError, ReferenceError, ScenarioError, SimError};
pub use model::{Input, RobotParams, RobotParamsSpec, State, Torques};
pub use plan::{Plan, SimConfig, Timing};
pub use scenario::{Overrides, Run, Scenario};
pub use sim::{Frame, Observer, Simulation};
