//! Fixtures the unit tests share.

use echelon::reference::{Circle, Reference};
use echelon::scenario::{FleetSettings, Overrides, Scenario};

use crate::StopFlag;
use crate::faults::FaultSpec;
use crate::net::NetOptions;
use crate::robot::RobotConfig;
use crate::up::free_ports;

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

/// Runs `serve` on a thread with options that listen on a free loopback TCP
/// port and a stop flag: the endpoint to connect to, the flag and the thread.
pub(crate) fn serve_on_loopback<T: Send + 'static>(
    serve: impl FnOnce(&NetOptions, &StopFlag) -> T + Send + 'static,
) -> (String, StopFlag, std::thread::JoinHandle<T>) {
    let port = free_ports(1).unwrap_or_else(|e| panic!("{e}"))[0];
    let endpoint = format!("tcp/127.0.0.1:{port}");
    let net = NetOptions {
        listen: vec![endpoint.clone()],
        ..NetOptions::default()
    };
    let stop = StopFlag::new();
    let thread = {
        let stop = stop.clone();
        std::thread::spawn(move || serve(&net, &stop))
    };
    (endpoint, stop, thread)
}
