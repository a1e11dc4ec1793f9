//! Fixtures the unit tests share.

use echelon::reference::{Circle, Reference};
use echelon::scenario::{FleetSettings, Overrides, Scenario};

use crate::StopFlag;
use crate::command::{FleetCommand, Order};
use crate::faults::FaultSpec;
use crate::net::NetOptions;
use crate::robot::RobotConfig;
use crate::token::OperatorToken;
use crate::up::free_ports;

/// The operator token of the unit tests: the robots of [`robot_config`]
/// hold it, and [`resume`] signs with it.
pub(crate) fn operator_token() -> OperatorToken {
    OperatorToken::parse("5eed0000000000000000000000000001").unwrap_or_else(|e| panic!("{e}"))
}

/// A resume numbered `seq` by `by` for `reason`, signed with
/// [`operator_token`].
pub(crate) fn resume(seq: u64, by: &str, reason: &str) -> FleetCommand {
    FleetCommand::new(Order::Resume, seq, by, reason).signed(&operator_token())
}

/// The CLI's process-test fleet (`echelon-cli/tests/fleet/fast-circle.toml`):
/// two robots in a chain behind a circle.
pub(crate) const FAST_CIRCLE: &str = include_str!("../../echelon-cli/tests/fleet/fast-circle.toml");

/// [`FAST_CIRCLE`]: the scenario, its fleet settings and its reference.
pub(crate) fn fast_circle() -> (Scenario, FleetSettings, Reference) {
    let s = Scenario::parse(FAST_CIRCLE, "test", None).unwrap_or_else(|e| panic!("{e}"));
    let fleet = s.fleet().unwrap_or_else(|e| panic!("{e}"));
    let reference = reference_of(&s);
    (s, fleet, reference)
}

/// The reference of `s`'s plan.
pub(crate) fn reference_of(s: &Scenario) -> Reference {
    s.build(&Overrides::default())
        .unwrap_or_else(|e| panic!("{e}"))
        .plan
        .reference()
        .clone()
}

/// The head of a test scenario of TurtleBot 4s (`[robots.tb4]`) under the
/// kinematic law with its point `l` ahead, named `name`, 30 s at 1 ms:
/// the reference, `[fleet]`, `[safety]` and agents follow.
pub(crate) fn tb4_kinematic(name: &str, l: f64) -> String {
    format!(
        r#"name = "{name}"
description = "{name}"
[sim]
duration = 30.0
dt = 0.001
[control]
law = "kinematic"
ke = 1.0
l = {l}
lycomp = "none"
ly_derivatives = "neglect"
[robots.tb4]
preset = "turtlebot4"
"#
    )
}

/// The circle through `start` at heading `heading`, driven at `speed` (m/s)
/// and `turn_rate` (rad/s): radius `speed / turn_rate`.
pub(crate) fn circle(start: [f64; 2], heading: f64, speed: f64, turn_rate: f64) -> Circle {
    Circle::new(start, heading, speed, turn_rate).expect("a valid circle")
}

/// Agent `agent`'s robot configuration in `s`, faults as given, running
/// until stopped, holding [`operator_token`].
pub(crate) fn robot_config(s: &Scenario, agent: u32, faults: FaultSpec) -> RobotConfig {
    let fleet = s.fleet().unwrap_or_else(|e| panic!("{e}"));
    let plan = s
        .build(&Overrides::default())
        .unwrap_or_else(|e| panic!("{e}"))
        .plan;
    let config = RobotConfig::from_plan(&plan, &fleet, agent, faults, None)
        .unwrap_or_else(|e| panic!("{e}"));
    RobotConfig {
        operator_token: Some(operator_token()),
        ..config
    }
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
