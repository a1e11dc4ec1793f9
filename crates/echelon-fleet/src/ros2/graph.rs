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

#[cfg(test)]
mod tests {
    use super::*;
    use echelon::scenario::Scenario;
    use echelon_ros2::graph::{Direction, GraphEndpoint, GraphProblem, check, parse_token};
    use echelon_ros2::liveliness::{Endpoint, NodeInfo, Qos};
    use proptest::prelude::*;

    /// Agent 1's link of a scenario with these `[fleet.ros2]` settings.
    fn link(
        ns: &str,
        stamped: bool,
        hazards: bool,
        estop: bool,
        driven: bool,
        bridge: bool,
    ) -> Ros2Link {
        let mut ros2 = format!(
            "namespace = \"{ns}\"\ncmd_vel_type = \"{}\"\ndriven = {driven}\nkey_scheme = \"{}\"\n",
            if stamped { "twist-stamped" } else { "twist" },
            if bridge { "bridge" } else { "rmw_zenoh" },
        );
        if hazards {
            ros2 += "hazards = \"hazard_detection\"\n";
        }
        if estop {
            ros2 += "estop = \"platform/emergency_stop\"\n";
        }
        let src = format!(
            "[sim]\nduration = 1.0\ndt = 0.01\n[reference.circle]\nspeed = 0.1\nturn_rate = 0.1\nstart = {{ x = 0.0, y = 0.0, theta = 0.0 }}\n[fleet.ros2]\n{ros2}[[agents]]\nstart = {{ x = 0.0, y = 0.0, theta = 0.0 }}\nleader = \"reference\"\n"
        );
        let s = Scenario::parse(&src, "t", None).unwrap_or_else(|e| panic!("{e}"));
        s.fleet().unwrap_or_else(|e| panic!("{e}")).ros2[0].clone()
    }

    /// The liveliness token announcing `e` as the robot's rmw_zenoh
    /// (echelon's own encoder, [`NodeInfo`]) or its zenoh-bridge-ros2dds
    /// (the format of the real bridge's captures) would.
    fn token(e: &Expected<'_>, bridge: bool, id: u64) -> String {
        if bridge {
            let kind = match e.direction {
                Direction::Publisher => "MP",
                Direction::Subscription => "MS",
            };
            return format!(
                "@/9a/@ros2_lv/{kind}/{}/{}/:1:::typehash={};",
                e.topic.trim_start_matches('/').replace('/', "§"),
                e.ty.name.replace('/', "§"),
                e.ty.hash
            );
        }
        let node = NodeInfo::new(0, "c0ffee", 1, "/", "base").unwrap_or_else(|e| panic!("{e}"));
        let kind = match e.direction {
            Direction::Publisher => Endpoint::Publisher,
            Direction::Subscription => Endpoint::Subscription,
        };
        node.endpoint_token(kind, id, e.topic, e.ty, &Qos::default())
    }

    proptest! {
        /// Over random namespaces, command types, optional hazard and
        /// e-stop topics, driven heads and both schemes: the graph that
        /// announces exactly what `expected` asks passes; without any one
        /// of its topics the check names that topic; with the other command
        /// type it names both types; under another namespace it says
        /// nothing is there. Arbitrary token text never panics the parser.
        #[test]
        fn the_check_names_exactly_what_is_wrong(
            ns in "[a-z][a-z0-9_]{0,8}",
            stamped in any::<bool>(),
            hazards in any::<bool>(),
            estop in any::<bool>(),
            driven in any::<bool>(),
            bridge in any::<bool>(),
            drop in any::<prop::sample::Index>(),
            junk in ".{0,80}",
        ) {
            let _ = parse_token(&junk);
            let l = link(&format!("/{ns}"), stamped, hazards, estop, driven, bridge);
            let want = expected(&l);
            prop_assert_eq!(want.len(), 1 + usize::from(!driven) + usize::from(hazards) + usize::from(estop));
            let seen: Vec<GraphEndpoint> = want
                .iter()
                .enumerate()
                .filter_map(|(i, e)| parse_token(&token(e, bridge, i as u64 + 2)))
                .collect();
            prop_assert_eq!(seen.len(), want.len());
            prop_assert_eq!(check(&seen, &l.namespace, &want), Ok(()));
            // One topic missing: named (an unrelated one keeps the namespace seen).
            let gone = drop.index(want.len());
            let mut fewer: Vec<GraphEndpoint> = seen.iter().enumerate().filter(|(i, _)| *i != gone).map(|(_, e)| e.clone()).collect();
            fewer.push(GraphEndpoint {
                direction: Direction::Publisher,
                topic: format!("{}/tf", l.namespace),
                type_name: "tf2_msgs/msg/TFMessage".to_owned(),
                hash: None,
            });
            match check(&fewer, &l.namespace, &want) {
                Err(GraphProblem::Missing { topic, .. }) => prop_assert_eq!(topic, want[gone].topic),
                other => prop_assert!(false, "{:?}", other),
            }
            // The other command type.
            if !driven {
                let other = link(&format!("/{ns}"), !stamped, hazards, estop, driven, bridge);
                let e = check(&seen, &l.namespace, &expected(&other)).expect_err("the other type");
                prop_assert!(matches!(e, GraphProblem::WrongCommandType { .. }), "{}", e);
                prop_assert!(e.to_string().contains(want[0].ty.name), "{}", e);
            }
            // Another namespace: nothing there, ours named.
            let elsewhere = format!("/x{ns}");
            let e = check(&seen, &elsewhere, &want).expect_err("elsewhere");
            prop_assert_eq!(e.to_string(), format!("nothing under {elsewhere}: topics seen under /{ns}"));
        }
    }
}
