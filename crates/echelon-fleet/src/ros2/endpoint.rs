//! A fleet process's ROS 2 presence (the robot's and `fleet excite`'s): a
//! node with a `cmd_vel` publisher and an `odom` subscription, as rmw_zenoh
//! declares them, and `cmd_vel` sent through Zenoh; the subscriptions are
//! the runtime's ([`crate::runtime`]).

use zenoh::Wait;

use echelon::scenario::Ros2Link;

use crate::FleetError;
use crate::ros2::declare_tokens;
use crate::ros2::drive::{CmdSink, cmd_vel_type};
use crate::ros2::fixes::fix_type;
use echelon_ros2::attachment::{Gid, gid_from_token};
use echelon_ros2::keys::{topic_key, topic_key_any_type};
use echelon_ros2::liveliness::{Endpoint, NodeInfo, Qos};
use echelon_ros2::msgs::{MessageType, ODOMETRY};
use echelon_ros2::names::NameError;

/// A ROS 2 node `<namespace>/<name>` of agent `link`'s with publishers and
/// subscriptions (topic, type), as rmw_zenoh declares them (liveliness
/// tokens, entity ids numbered from 1 in that order); its tokens and its
/// publishers' gids, in order.
pub(crate) fn declare_node(
    session: &zenoh::Session,
    link: &Ros2Link,
    name: &str,
    publishes: &[(&str, &MessageType)],
    subscribes: &[(&str, &MessageType)],
    name_error: impl FnOnce(NameError) -> FleetError,
) -> Result<(Vec<zenoh::liveliness::LivelinessToken>, Vec<Gid>), FleetError> {
    let zid = session.zid().to_string();
    let node = NodeInfo::new(link.domain_id, &zid, 0, &link.namespace, name)
        .map_err(name_error)?
        .with_scheme(link.key_scheme);
    let mut id = 0;
    let mut next = || {
        id += 1;
        id
    };
    let publishers: Vec<String> = publishes
        .iter()
        .map(|(topic, ty)| {
            node.endpoint_token(Endpoint::Publisher, next(), topic, ty, &Qos::default())
        })
        .collect();
    let mut tokens = vec![node.node_token()];
    tokens.extend(publishers.iter().cloned());
    tokens.extend(subscribes.iter().map(|(topic, ty)| {
        node.endpoint_token(Endpoint::Subscription, next(), topic, ty, &Qos::default())
    }));
    let tokens = declare_tokens(session, &tokens)?;
    Ok((
        tokens,
        publishers.iter().map(|t| gid_from_token(t)).collect(),
    ))
}

/// Agent `k`'s ROS 2 node `<namespace>/echelon_robot` as rmw_zenoh declares
/// it (liveliness tokens: the node, a `cmd_vel` publisher, an `odom`
/// subscription and, with fixes, their subscription) and its `cmd_vel`
/// publisher; the subscriptions themselves are its user's.
pub(crate) struct Ros2Node {
    pub(crate) publisher: zenoh::pubsub::Publisher<'static>,
    pub(crate) gid: Gid,
    /// The key expression of its `odom`, any type (so that a publisher of
    /// the wrong type is seen, counted and refused rather than never heard).
    pub(crate) odom_key: String,
    /// The key expression of its fixes (any type), when it takes any.
    pub(crate) fix_key: Option<String>,
    pub(crate) tokens: Vec<zenoh::liveliness::LivelinessToken>,
}

impl Ros2Node {
    pub(crate) fn declare(
        session: &zenoh::Session,
        link: &Ros2Link,
        agent: u32,
    ) -> Result<Ros2Node, FleetError> {
        let cmd_type = cmd_vel_type(link);
        let mut subscribes = vec![(link.odom.as_str(), &ODOMETRY)];
        if let Some(f) = &link.fixes {
            subscribes.push((f.topic.as_str(), fix_type(f.message)));
        }
        let (tokens, gids) = declare_node(
            session,
            link,
            "echelon_robot",
            &[(&link.cmd_vel, &cmd_type)],
            &subscribes,
            |e| FleetError::Config(format!("agent {agent}: {e}")),
        )?;
        let cmd_key = topic_key(link.key_scheme, link.domain_id, &link.cmd_vel, &cmd_type);
        let publisher = session
            .declare_publisher(cmd_key.clone())
            .wait()
            .map_err(|e| FleetError::Zenoh(format!("declaring {cmd_key}: {e}")))?;
        Ok(Ros2Node {
            publisher,
            gid: gids[0],
            odom_key: topic_key_any_type(link.key_scheme, link.domain_id, &link.odom),
            fix_key: link
                .fixes
                .as_ref()
                .map(|f| topic_key_any_type(link.key_scheme, link.domain_id, &f.topic)),
            tokens,
        })
    }
}

/// `cmd_vel` through a Zenoh publisher it owns, stamped by the system clock.
pub(crate) struct OwnedCmdSink(pub(crate) zenoh::pubsub::Publisher<'static>);

impl std::fmt::Debug for OwnedCmdSink {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("OwnedCmdSink")
    }
}

impl CmdSink for OwnedCmdSink {
    fn now_ns(&self) -> i64 {
        ZenohCmdSink(&self.0).now_ns()
    }
    fn send(&mut self, payload: &[u8], attachment: &[u8]) -> Result<(), String> {
        ZenohCmdSink(&self.0).send(payload, attachment)
    }
}

/// `cmd_vel` through a Zenoh publisher, stamped by the system clock.
pub(crate) struct ZenohCmdSink<'a, 'b>(pub(crate) &'a zenoh::pubsub::Publisher<'b>);

impl std::fmt::Debug for ZenohCmdSink<'_, '_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("ZenohCmdSink")
    }
}

impl CmdSink for ZenohCmdSink<'_, '_> {
    fn now_ns(&self) -> i64 {
        crate::unix_nanos() as i64
    }
    fn send(&mut self, payload: &[u8], attachment: &[u8]) -> Result<(), String> {
        self.0
            .put(payload.to_vec())
            .attachment(attachment.to_vec())
            .wait()
            .map_err(|e| e.to_string())
    }
}
