//! # echelon-core
//!
//! The kernel of echelon: leader-follower formation control of
//! differential-drive robots, after *Leader-Follower Control with Odometry
//! Error Analysis* (the paper), with the corrections of
//! `docs/control-law.md`. Plain data and math, no IO: no files, no TOML, no
//! CSV, no ROS; serde derives only with the `serde` feature. Embed it in a
//! controller, a simulator or a learning environment; the scenario format,
//! outputs and studies are the `echelon` crate's, above this one.
//!
//! - [`model`]: the plant, a unicycle with mass, inertia, viscous friction and
//!   wheel torques (eqs. 1–3, Table I);
//! - [`reference`](mod@reference): reference trajectories with exact derivatives (eqs. 17–20,
//!   lines, timed waypoints);
//! - [`lycomp`]: where a follower holds its leader, `L_X`, `L_Y` and the curvature
//!   compensation `L_Ycomp` (eqs. 4–6);
//! - [`control`]: the backstepping law (eqs. 7–16);
//! - [`kinematic`]: the kinematic law, its first step used as a velocity
//!   command, for velocity-controlled bases;
//! - [`base`]: a velocity-controlled base (lags, speed and acceleration
//!   limits, presets for real robots);
//! - [`agent`]: one agent's robot, law, leader and placement;
//! - [`follow`]: one agent's law evaluation behind what it knows of its leader;
//! - [`formation`]: who follows whom; [`plan`]: a built run as plain data;
//! - [`sim`]: the RK4 simulator and its observers;
//! - [`sample`]: one agent at one instant, what every log and the fleet carry;
//! - [`guard`]: the divergence guard (physical bounds on a state);
//! - [`odometry`]: encoders, dead reckoning, error models, fixes, the EKF;
//! - [`engine`]: the batch engine, the same system for thousands of agents at
//!   a time (SIMD lanes, all cores);
//! - [`lanes`]: the number types the law is written for, and SIMD lanes;
//! - [`safety`]: barrier-certificate safety filter between robots and around obstacles;
//! - [`rng`]: the seeded random streams; [`check`], [`error`]: parameter
//!   checks and the kernel's typed errors.
//!
//! Units are SI and angles radians throughout (ROS REP 103).

#![cfg_attr(not(test), warn(clippy::too_many_lines))]

pub mod agent;
pub mod base;
pub mod check;
pub mod control;
pub mod engine;
pub mod error;
pub mod follow;
pub mod formation;
pub mod guard;
pub mod kinematic;
pub mod lanes;
pub mod learn;
pub mod lycomp;
pub mod math;
pub mod model;
pub mod odometry;
pub mod plan;
pub mod reference;
pub mod rng;
pub mod safety;
pub mod sample;
pub mod sim;
mod spline;

pub use agent::{AgentSpec, Command};
pub use control::{Gains, Variant};
pub use error::{FormationError, ParamError, ReferenceError, SimError};
pub use model::{Input, RobotParams, RobotParamsSpec, State, Torques};
pub use plan::{Plan, SimConfig, Timing};
pub use sim::{Frame, Observer, Simulation};
