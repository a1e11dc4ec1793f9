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
//! Twelve modules, the rest in their folders:
//!
//! - [`model`]: the plant, a unicycle with mass, inertia, viscous friction and
//!   wheel torques (eqs. 1–3, Table I); [`model::base`]: a velocity-controlled
//!   base (lags, speed and acceleration limits, presets for real robots);
//! - [`reference`](mod@reference): reference trajectories with exact derivatives (eqs. 17–20,
//!   lines, timed waypoints);
//! - [`law`]: [`law::lycomp`], where a follower holds its leader, `L_X`, `L_Y`
//!   and the curvature compensation `L_Ycomp` (eqs. 4–6); [`law::control`],
//!   the backstepping law (eqs. 7–16); [`law::kinematic`], its first step
//!   used as a velocity command, for velocity-controlled bases;
//! - [`formation`]: who follows whom; [`formation::agent`]: one agent's robot,
//!   law, leader and placement; [`formation::follow`]: one agent's law
//!   evaluation behind what it knows of its leader;
//! - [`sim`]: the RK4 simulator and its observers; [`sim::plan`]: a built run
//!   as plain data; [`sim::sample`]: one agent at one instant, what every log
//!   and the fleet carry; [`sim::guard`]: the divergence guard (physical
//!   bounds on a state);
//! - [`odometry`]: encoders, dead reckoning, error models, fixes, the EKF;
//! - [`engine`]: the batch engine, the same system for thousands of agents at
//!   a time (SIMD lanes, all cores); [`learn`]: the vectorised environment
//!   over it;
//! - [`safety`]: barrier-certificate safety filter between robots and around obstacles;
//! - [`math`]: small numerical helpers, [`math::lanes`] (the number types the
//!   law is written for, and SIMD lanes) and [`math::rng`] (the seeded random
//!   streams); [`check`], [`error`]: parameter checks and the kernel's typed
//!   errors.
//!
//! Units are SI and angles radians throughout (ROS REP 103).

#![cfg_attr(not(test), warn(clippy::too_many_lines))]

pub mod check;
pub mod engine;
pub mod error;
pub mod formation;
pub mod law;
pub mod learn;
pub mod math;
pub mod model;
pub mod odometry;
pub mod reference;
pub mod safety;
pub mod sim;

pub use error::{FormationError, ParamError, ReferenceError, SimError};
pub use formation::agent::{AgentSpec, Command};
pub use law::control::{Gains, Variant};
pub use model::{Input, RobotParams, RobotParamsSpec, State, Torques};
pub use sim::plan::{Plan, SimConfig, Timing};
pub use sim::{Frame, Observer, Simulation};
