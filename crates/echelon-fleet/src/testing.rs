//! Fixtures the unit tests share.

use echelon::reference::{Circle, Reference};
use echelon::scenario::{FleetSettings, Overrides, Scenario};

use crate::faults::FaultSpec;
use crate::robot::RobotConfig;

/// The CLI's process-test fleet (`echelon-cli/tests/fleet/fast-circle.toml`):
/// two robots in a chain behind a circle.
pub(crate) const FAST_CIRCLE: &str = include_str!("../../echelon-cli/tests/fleet/fast-circle.toml");

/// [`FAST_CIRCLE`]: the scenario, its fleet settings and its reference.
pub(crate) fn fast_circle() -> (Scenario, FleetSettings, Reference) {
    let s = Scenario::parse(FAST_CIRCLE, "test", None).unwrap_or_else(|e| panic!("{e}"));
    let fleet = s.fleet().unwrap_or_else(|e| panic!("{e}"));
    let reference = s
        .build(&Overrides::default())
        .unwrap_or_else(|e| panic!("{e}"))
        .plan
        .reference()
        .clone();
    (s, fleet, reference)
}

/// The circle through `start` at heading `heading`, driven at `speed` (m/s)
/// and `turn_rate` (rad/s): radius `speed / turn_rate`.
pub(crate) fn circle(start: [f64; 2], heading: f64, speed: f64, turn_rate: f64) -> Circle {
    Circle::new(start, heading, speed, turn_rate).expect("a valid circle")
}

/// Agent `agent`'s robot configuration in `s`, faults as given, running
/// until stopped.
pub(crate) fn robot_config(s: &Scenario, agent: u32, faults: FaultSpec) -> RobotConfig {
    let fleet = s.fleet().unwrap_or_else(|e| panic!("{e}"));
    let plan = s
        .build(&Overrides::default())
        .unwrap_or_else(|e| panic!("{e}"))
        .plan;
    RobotConfig::from_plan(&plan, &fleet, agent, faults, None).unwrap_or_else(|e| panic!("{e}"))
}
