//! A robot's ROS 2 graph as its Zenoh side announces it, and the check that
//! it is the robot the scenario describes, before anything moves.
//!
//! Both ways echelon reaches a robot announce every publisher and
//! subscription with a liveliness token:
//!
//! - **rmw_zenoh** (a robot on ROS 2's Zenoh middleware): `@ros2_lv/<domain>/
//!   <zid>/<node id>/<entity id>/<MP|MS|…>/<enclave>/<namespace>/<node>/
//!   <topic>/<DDS type>/<hash>/<qos>`, names mangled (`/` → `%`), the type
//!   as DDS names it (`geometry_msgs::msg::dds_::Twist_`) ([`crate::liveliness`]);
//! - **zenoh-bridge-ros2dds** (a robot left on DDS), one token per route:
//!   `@/<zid>/@ros2_lv/<MP|MS|SS|SC|AS|AC>/<key>/<type>[/<qos>]`, where
//!   `<key>` is the Zenoh key the topic is routed on (its ROS name under the
//!   bridge's namespace, without the leading `/`) and `<type>` the ROS type
//!   (`geometry_msgs/msg/Twist`), each with `/` written `§`; `MP` is a DDS
//!   publisher routed to Zenoh, `MS` a DDS subscriber fed from Zenoh; the
//!   QoS part ends with `typehash=RIHS01_…;` from a Jazzy node (none from
//!   Humble), after QoS fields that depend on the DDS vendor.
//!
//! [`parse_token`] reads either into a [`GraphEndpoint`] (topic as a fully
//! qualified ROS name, type as `pkg/msg/Type`); [`check`] answers whether a
//! robot's `cmd_vel` has a subscriber of the type echelon sends and its
//! `odom` (and hazard and e-stop topics, when configured) a publisher, and
//! otherwise says in one line what it found instead
//! ([`GraphProblem`]). The fleet asks the tokens (`echelon_fleet::ros2`)
//! and exits 2 with that line; the golden captures of the real bridge
//! (`echelon-fleet/tests/fixtures/ros2dds/`) are read by its tests.

use std::collections::BTreeSet;

use crate::liveliness::ADMIN_SPACE;
use crate::msgs::MessageType;

/// Which side of a topic an endpoint is.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum Direction {
    /// It publishes (`MP`).
    Publisher,
    /// It subscribes (`MS`).
    Subscription,
}

/// One publisher or subscription of the robot's graph.
#[derive(Debug, Clone, PartialEq, Eq, PartialOrd, Ord)]
pub struct GraphEndpoint {
    /// Publisher or subscription.
    pub direction: Direction,
    /// The topic, fully qualified (`/bot1/cmd_vel`).
    pub topic: String,
    /// Its type, `pkg/msg/Type`.
    pub type_name: String,
    /// Its RIHS01 hash, when the token carries one.
    pub hash: Option<String>,
}

/// The liveliness key expressions whose tokens describe the graph of a
/// robot in `domain_id`: rmw_zenoh's, and zenoh-bridge-ros2dds's (`@/<zid>/`
/// then the same admin space; the bridge routes one domain).
pub fn tokens_keyexprs(domain_id: u32) -> [String; 2] {
    [
        format!("{ADMIN_SPACE}/{domain_id}/**"),
        format!("@/*/{ADMIN_SPACE}/**"),
    ]
}

/// `geometry_msgs::msg::dds_::Twist_` → `geometry_msgs/msg/Twist`.
fn ros_type_of_dds(dds: &str) -> Option<String> {
    let (namespace, ty) = dds.rsplit_once("::dds_::")?;
    let ty = ty.strip_suffix('_')?;
    Some(format!("{}/{ty}", namespace.replace("::", "/")))
}

fn direction(code: &str) -> Option<Direction> {
    match code {
        "MP" => Some(Direction::Publisher),
        "MS" => Some(Direction::Subscription),
        _ => None,
    }
}

/// A publisher or subscription from one liveliness token of either scheme
/// (`None`: a node, service or action token, or not a token of ROS 2's).
pub fn parse_token(token: &str) -> Option<GraphEndpoint> {
    let chunks: Vec<&str> = token.split('/').collect();
    match chunks.as_slice() {
        // zenoh-bridge-ros2dds: @/<zid>/@ros2_lv/<kind>/<key>/<type>[/<qos>]
        ["@", _zid, admin, kind, key, ty, rest @ ..]
            if *admin == ADMIN_SPACE && rest.len() <= 1 =>
        {
            let direction = direction(kind)?;
            let key = key.replace('§', "/");
            let hash = rest.first().and_then(|qos| {
                let (_, h) = qos.split_once("typehash=")?;
                Some(h.trim_end_matches(';').to_owned())
            });
            Some(GraphEndpoint {
                direction,
                topic: format!("/{}", key.trim_start_matches('/')),
                type_name: ty.replace('§', "/"),
                hash,
            })
        }
        // rmw_zenoh: @ros2_lv/<domain>/<zid>/<nid>/<eid>/<kind>/<enclave>/<ns>/<node>/<topic>/<type>/<hash>/<qos>
        [
            admin,
            _domain,
            _zid,
            _nid,
            _eid,
            kind,
            _enclave,
            _ns,
            _node,
            topic,
            ty,
            hash,
            _qos,
        ] if *admin == ADMIN_SPACE => Some(GraphEndpoint {
            direction: direction(kind)?,
            topic: topic.replace('%', "/"),
            type_name: ros_type_of_dds(&ty.replace('%', "/"))?,
            hash: hash.starts_with("RIHS01_").then(|| (*hash).to_owned()),
        }),
        _ => None,
    }
}

/// One topic the robot must have, and on which side.
#[derive(Debug, Clone, Copy)]
pub struct Expected<'a> {
    /// What it is for, in the messages (`cmd_vel`, `odom`, `hazards`).
    pub role: &'a str,
    /// The topic, fully qualified.
    pub topic: &'a str,
    /// Its type.
    pub ty: &'a MessageType,
    /// The side the robot must be on (a subscription for `cmd_vel`).
    pub direction: Direction,
}

/// What is wrong with a robot's graph, as one line.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum GraphProblem {
    /// Nothing at all under the robot's namespace.
    #[error("nothing under {namespace}: {}", seen_under(.seen))]
    NothingUnder {
        /// The namespace.
        namespace: String,
        /// The namespaces (first name of each topic) that were seen.
        seen: Vec<String>,
    },
    /// A topic is there with another type than echelon uses.
    #[error("{role} takes {found}, the scenario sends {}", short(.expected))]
    WrongCommandType {
        /// `cmd_vel`.
        role: String,
        /// The type the robot subscribes with.
        found: String,
        /// The type echelon sends.
        expected: String,
    },
    /// A topic is there with another type than echelon reads.
    #[error("{role} is published as {found}, echelon reads {expected}")]
    WrongType {
        /// `odom`, `hazards`, `estop`.
        role: String,
        /// The type found.
        found: String,
        /// The type echelon reads.
        expected: String,
    },
    /// The same type with another hash: another version of the message.
    #[error(
        "{role} ({topic}) has type {type_name} with hash {found}, echelon's is {expected}: another version of the message"
    )]
    WrongHash {
        /// `cmd_vel`, `odom`, …
        role: String,
        /// The topic.
        topic: String,
        /// The type.
        type_name: String,
        /// The hash found.
        found: String,
        /// echelon's.
        expected: String,
    },
    /// No endpoint on the topic on the side needed.
    #[error("no {} of {topic} ({role}){}", side(.direction), seen_there(.others))]
    Missing {
        /// What it is for.
        role: String,
        /// The topic.
        topic: String,
        /// The side missing.
        direction: Direction,
        /// The topics of that side seen under the namespace.
        others: Vec<String>,
    },
}

fn seen_under(seen: &[String]) -> String {
    match seen {
        [] => "no ROS 2 topic seen at all".to_owned(),
        s => format!("topics seen under {}", s.join(", ")),
    }
}

fn side(d: &Direction) -> &'static str {
    match d {
        Direction::Publisher => "publisher",
        Direction::Subscription => "subscriber",
    }
}

fn seen_there(others: &[String]) -> String {
    match others {
        [] => String::new(),
        o => format!("; seen there: {}", o.join(", ")),
    }
}

/// `geometry_msgs/msg/Twist` → `Twist`.
fn short(name: &str) -> &str {
    name.rsplit('/').next().unwrap_or(name)
}

/// The first name of a fully qualified topic (`/bot1/cmd_vel` → `/bot1`).
fn first_name(topic: &str) -> String {
    let name = topic.trim_start_matches('/');
    format!("/{}", name.split('/').next().unwrap_or(name))
}

/// Checks the graph `seen` of the robot under `namespace` against what the
/// scenario expects, in order: anything under the namespace at all; then
/// each expected topic on its side, of its type (and hash, when both sides
/// carry one). The first problem found is returned.
pub fn check(
    seen: &[GraphEndpoint],
    namespace: &str,
    expected: &[Expected<'_>],
) -> Result<(), GraphProblem> {
    let ns = namespace.trim_end_matches('/');
    let under = |topic: &str| ns.is_empty() || topic.starts_with(&format!("{ns}/"));
    if !seen.iter().any(|e| under(&e.topic)) {
        let seen: BTreeSet<String> = seen.iter().map(|e| first_name(&e.topic)).collect();
        return Err(GraphProblem::NothingUnder {
            namespace: if ns.is_empty() {
                "/".to_owned()
            } else {
                ns.to_owned()
            },
            seen: seen.into_iter().collect(),
        });
    }
    for x in expected {
        let on_topic: Vec<&GraphEndpoint> = seen
            .iter()
            .filter(|e| e.topic == x.topic && e.direction == x.direction)
            .collect();
        if on_topic.is_empty() {
            let others: BTreeSet<String> = seen
                .iter()
                .filter(|e| e.direction == x.direction && under(&e.topic))
                .map(|e| format!("{} ({})", e.topic, short(&e.type_name)))
                .collect();
            return Err(GraphProblem::Missing {
                role: x.role.to_owned(),
                topic: x.topic.to_owned(),
                direction: x.direction,
                others: others.into_iter().collect(),
            });
        }
        let right_type: Vec<&&GraphEndpoint> = on_topic
            .iter()
            .filter(|e| e.type_name == x.ty.name)
            .collect();
        let Some(first) = right_type.first() else {
            let found = on_topic[0].type_name.clone();
            return Err(match x.direction {
                Direction::Subscription => GraphProblem::WrongCommandType {
                    role: x.role.to_owned(),
                    found,
                    expected: x.ty.name.to_owned(),
                },
                Direction::Publisher => GraphProblem::WrongType {
                    role: x.role.to_owned(),
                    found,
                    expected: x.ty.name.to_owned(),
                },
            });
        };
        let hash_ok = right_type
            .iter()
            .any(|e| e.hash.as_deref().is_none_or(|h| h == x.ty.hash));
        if !hash_ok {
            return Err(GraphProblem::WrongHash {
                role: x.role.to_owned(),
                topic: x.topic.to_owned(),
                type_name: x.ty.name.to_owned(),
                found: first.hash.clone().unwrap_or_default(),
                expected: x.ty.hash.to_owned(),
            });
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::liveliness::{Endpoint, NodeInfo, Qos};
    use crate::msgs::{ODOMETRY, TWIST, TWIST_STAMPED};
    use crate::names::KeyScheme;

    fn expected<'a>(cmd: &'a MessageType) -> [Expected<'a>; 2] {
        [
            Expected {
                role: "cmd_vel",
                topic: "/bot1/cmd_vel",
                ty: cmd,
                direction: Direction::Subscription,
            },
            Expected {
                role: "odom",
                topic: "/bot1/odom",
                ty: &ODOMETRY,
                direction: Direction::Publisher,
            },
        ]
    }

    /// rmw_zenoh's tokens as echelon writes them ([`NodeInfo`]) read back.
    #[test]
    fn rmw_zenoh_tokens_round_trip() {
        let node = NodeInfo::new(0, "c0ffee", 3, "/bot1", "base").expect("valid");
        let sub = node.endpoint_token(
            Endpoint::Subscription,
            4,
            "/bot1/cmd_vel",
            &TWIST,
            &Qos::default(),
        );
        let p = parse_token(&sub).expect("an endpoint");
        assert_eq!(
            p,
            GraphEndpoint {
                direction: Direction::Subscription,
                topic: "/bot1/cmd_vel".to_owned(),
                type_name: TWIST.name.to_owned(),
                hash: Some(TWIST.hash.to_owned()),
            }
        );
        assert_eq!(parse_token(&node.node_token()), None);
        let humble = node.clone().with_scheme(KeyScheme::RmwZenohHumble);
        let pub_ = humble.endpoint_token(
            Endpoint::Publisher,
            5,
            "/bot1/odom",
            &ODOMETRY,
            &Qos::default(),
        );
        assert_eq!(parse_token(&pub_).and_then(|p| p.hash), None);
    }

    #[test]
    fn the_usual_mistakes_are_named() {
        let bridge = |kind: &str, key: &str, ty: &str| {
            format!(
                "@/9a/@ros2_lv/{kind}/{}/{}/:1:::typehash=RIHS01_x;",
                key.replace('/', "§"),
                ty.replace('/', "§")
            )
        };
        let tokens = [
            bridge("MS", "bot1/cmd_vel", "geometry_msgs/msg/TwistStamped"),
            bridge("MP", "bot1/odom", "nav_msgs/msg/Odometry"),
        ];
        let seen: Vec<GraphEndpoint> = tokens.iter().filter_map(|t| parse_token(t)).collect();
        assert_eq!(seen.len(), 2);
        let e = check(&seen, "/bot1", &expected(&TWIST)).expect_err("wrong type");
        assert_eq!(
            e.to_string(),
            "cmd_vel takes geometry_msgs/msg/TwistStamped, the scenario sends Twist"
        );
        // The bridge's typehash placeholder is not echelon's: another version.
        let e = check(&seen, "/bot1", &expected(&TWIST_STAMPED)).expect_err("hash");
        assert!(matches!(e, GraphProblem::WrongHash { .. }), "{e}");
        let e = check(&seen, "/tb4_red", &expected(&TWIST_STAMPED)).expect_err("namespace");
        assert_eq!(
            e.to_string(),
            "nothing under /tb4_red: topics seen under /bot1"
        );
        let only_cmd = &seen[..1];
        let mut right = only_cmd.to_vec();
        right[0].hash = None;
        let e = check(&right, "/bot1", &expected(&TWIST_STAMPED)).expect_err("no odom");
        assert_eq!(e.to_string(), "no publisher of /bot1/odom (odom)");
        assert_eq!(
            check(&[], "/bot1", &[]).map_err(|e| e.to_string()),
            Err("nothing under /bot1: no ROS 2 topic seen at all".to_owned())
        );
    }
}
