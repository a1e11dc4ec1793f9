//! The robot's ROS 2 graph checked before anything moves: its `cmd_vel`
//! has a subscriber of the type echelon sends, its `odom` a publisher (and
//! its hazard and e-stop topics, when the scenario names them), read from
//! the liveliness tokens its rmw_zenoh or zenoh-bridge-ros2dds declares
//! ([`echelon_ros2::graph`]). Otherwise one line names the robot and what
//! was found, and the process exits 2 (`fleet robot --ros2`, `fleet up
//! --ros2`); the lab's `fleet doctor` is meant to call the same check.

use std::time::{Duration, Instant};

use zenoh::Wait;

use echelon::scenario::Ros2Link;
use echelon_ros2::graph::{self, Direction, Expected, GraphEndpoint, GraphProblem};

use crate::FleetError;
use crate::ros2::drive::{DriveInput, cmd_vel_type};

/// How long a real robot's graph is awaited, real time: a bridge announces
/// a DDS node's topics within a second or two of discovering it.
pub const GRAPH_WAIT: Duration = Duration::from_secs(5);
/// How long a simulated base's graph is awaited (`fleet up --ros2`: the
/// base starts beside the robot, on a machine that may be loaded).
pub const GRAPH_WAIT_SIMULATED: Duration = Duration::from_secs(30);
/// How often the tokens are asked again while waiting.
const POLL: Duration = Duration::from_millis(250);

/// What the robot at `link` must have: `cmd_vel` subscribed to with the
/// type echelon sends (unless someone else drives it), `odom` published,
/// its hazards and e-stop published when configured.
pub fn expected(link: &Ros2Link) -> Vec<Expected<'_>> {
    let command = (!link.driven).then(|| Expected {
        role: "cmd_vel",
        topic: &link.cmd_vel,
        ty: cmd_vel_type(link),
        direction: Direction::Subscription,
    });
    // The drive's inputs but its fixes (a motion capture's, often another
    // machine's and namespace's).
    let read = DriveInput::of_link(link)
        .into_iter()
        .filter(|(input, _)| *input != DriveInput::Fixes)
        .map(|(input, topic)| Expected {
            role: input.role(),
            topic,
            ty: input.message_type(link),
            direction: Direction::Publisher,
        });
    command.into_iter().chain(read).collect()
}

/// The publishers and subscriptions announced on `session` now.
pub fn seen(session: &zenoh::Session, domain_id: u32) -> Result<Vec<GraphEndpoint>, FleetError> {
    let mut seen = Vec::new();
    for keyexpr in graph::tokens_keyexprs(domain_id) {
        let replies = session
            .liveliness()
            .get(keyexpr.as_str())
            .timeout(Duration::from_millis(500))
            .wait()
            .map_err(|e| FleetError::Zenoh(format!("liveliness {keyexpr}: {e}")))?;
        while let Ok(reply) = replies.recv() {
            if let Ok(s) = reply.result()
                && let Some(e) = graph::parse_token(s.key_expr().as_str())
            {
                seen.push(e);
            }
        }
    }
    seen.sort();
    seen.dedup();
    Ok(seen)
}

/// Waits up to `within` for agent `agent`'s robot at `link`, on `session`,
/// to show the graph the scenario describes; otherwise
/// [`FleetError::Graph`] with one line naming the robot and what was found.
pub fn check_robot(
    session: &zenoh::Session,
    link: &Ros2Link,
    agent: u32,
    within: Duration,
    stop: &crate::StopFlag,
) -> Result<(), FleetError> {
    let at = match link.connect.as_slice() {
        [] => String::new(),
        c => format!("; its router at {}", c.join(" or ")),
    };
    let started = Instant::now();
    let expected = expected(link);
    loop {
        let problem: GraphProblem =
            match graph::check(&seen(session, link.domain_id)?, &link.namespace, &expected) {
                Ok(()) => return Ok(()),
                Err(p) => p,
            };
        if started.elapsed() >= within || stop.is_raised() {
            return Err(FleetError::Graph(format!(
                "agent {agent}: {problem} (after {:.1} s; checked from the liveliness tokens its rmw_zenoh or zenoh-bridge-ros2dds announces{at})",
                started.elapsed().as_secs_f64()
            )));
        }
        std::thread::sleep(POLL);
    }
}
