//! # echelon
//!
//! Leader-follower formation control of differential-drive robots, after
//! *Leader-Follower Control with Odometry Error Analysis* (the paper), with the
//! corrections of `docs/control-law.md`.
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
//! - [`follow`]: one agent's law evaluation behind what it knows of its leader;
//! - [`formation`]: who follows whom;
//! - [`sim`]: the RK4 simulator and its observers;
//! - [`sample`]: one agent at one instant, what every log and the fleet carry;
//! - [`stats`]: run statistics (per agent, safety, divergence);
//! - [`odometry`]: encoders, dead reckoning, error models, fixes, Theorem 2, UMBmark;
//! - [`sweep`]: Monte Carlo sweeps over odometry errors and fix intervals;
//! - [`engine`]: the batch engine, the same system for thousands of agents at
//!   a time (SIMD lanes, all cores), and `echelon bench`'s formation;
//! - [`lanes`]: the number types the law is written for, and SIMD lanes;
//! - [`scenario`]: the TOML scenario format and the paper's built-in setups;
//! - [`safety`]: barrier-certificate safety filter between robots and around obstacles;
//! - [`output`]: `trajectory.csv` and `summary.json`;
//! - [`identify`]: a robot's eq. 3 parameters or velocity-base lags from its logs;
//! - [`lm`]: Levenberg–Marquardt for the small least-squares fits.
//!
//! Units are SI and angles radians throughout (ROS REP 103).

pub mod agent;
pub mod base;
pub mod check;
pub mod control;
pub mod csv;
pub mod engine;
pub mod error;
pub mod follow;
pub mod formation;
pub mod guard;
pub mod identify;
pub mod kinematic;
pub mod lanes;
pub mod lm;
pub mod lycomp;
mod math;
pub mod model;
pub mod odometry;
pub mod output;
pub mod plan;
pub mod reference;
pub mod rng;
pub mod safety;
pub mod sample;
pub mod scenario;
pub mod sim;
mod spline;
pub mod stats;
pub mod sweep;

pub use agent::{AgentSpec, Command};
pub use control::{Gains, Variant};
pub use error::{FormationError, OutputError, ParamError, ReferenceError, ScenarioError, SimError};
pub use model::{Input, RobotParams, RobotParamsSpec, State, Torques};
pub use plan::{Plan, SimConfig, Timing};
pub use scenario::{Overrides, Run, Scenario};
pub use sim::{Frame, Observer, Simulation};
