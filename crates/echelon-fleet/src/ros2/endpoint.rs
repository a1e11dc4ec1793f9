//! A fleet process's ROS 2 presence (the robot's and `fleet excite`'s): a
//! node with a `cmd_vel` publisher and an `odom` subscription, as rmw_zenoh
//! declares them, and `cmd_vel` sent through Zenoh; the subscriptions are
//! the runtime's ([`crate::runtime`]).

use zenoh::Wait;
use zenoh::qos::CongestionControl;

use echelon::scenario::Ros2Link;

use crate::FleetError;
use crate::ros2::declare_tokens;
use crate::ros2::drive::{CmdSink, DriveInput, cmd_vel_type};
use echelon_ros2::attachment::{Gid, gid_from_token};
use echelon_ros2::keys::{topic_key, topic_key_any_type};
use echelon_ros2::liveliness::{Endpoint, NodeInfo, Qos};
use echelon_ros2::msgs::MessageType;
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
/// subscription and, when configured, its fixes', hazards' and e-stop's)
/// and its `cmd_vel` publisher; the subscriptions themselves are its user's.
pub(crate) struct Ros2Node {
    pub(crate) publisher: CmdPublisher,
    pub(crate) gid: Gid,
    /// The key expressions of the drive's inputs, in their numbering
    /// ([`DriveInput::of_link`]), each of any type (so that a publisher of
    /// the wrong type is seen, counted and refused rather than never heard):
    /// `odom` first.
    pub(crate) input_keys: Vec<String>,
    pub(crate) tokens: Vec<zenoh::liveliness::LivelinessToken>,
}

impl Ros2Node {
    pub(crate) fn declare(
        session: &zenoh::Session,
        link: &Ros2Link,
        agent: u32,
    ) -> Result<Ros2Node, FleetError> {
        let cmd_type = cmd_vel_type(link);
        let inputs = DriveInput::of_link(link);
        let subscribes: Vec<(&str, &MessageType)> = inputs
            .iter()
            .map(|&(input, topic)| (topic, input.message_type(link)))
            .collect();
        let (tokens, gids) = declare_node(
            session,
            link,
            "echelon_robot",
            &[(&link.cmd_vel, cmd_type)],
            &subscribes,
            |e| FleetError::Config(format!("agent {agent}: {e}")),
        )?;
        let cmd_key = topic_key(link.key_scheme, link.domain_id, &link.cmd_vel, cmd_type);
        let publisher = CmdPublisher::declare(session, cmd_key)?;
        Ok(Ros2Node {
            publisher,
            gid: gids[0],
            input_keys: inputs
                .iter()
                .map(|(_, topic)| topic_key_any_type(link.key_scheme, link.domain_id, topic))
                .collect(),
            tokens,
        })
    }
}

/// A robot's two Zenoh publishers of its `cmd_vel` (one key, one ROS 2
/// publisher as rmw_zenoh declares it: the liveliness token is the node's).
///
/// Every command of the control loop goes out through `each`, with Zenoh's
/// default congestion control (`Drop`): a put never blocks the loop, which
/// ticks on Zenoh's own runtime thread (`runtime/drive.rs`) where a blocked
/// put would hold up the very transmission task it waits for; a dropped
/// command is superseded by the next tick's. A stop's zero goes out through
/// `last`, with `CongestionControl::Block` (as rmw_zenoh publishes reliable
/// topics): no queue on its way (this process's or a router's) drops it;
/// it may be the last command the robot ever sends.
pub(crate) struct CmdPublisher {
    pub(crate) each: zenoh::pubsub::Publisher<'static>,
    pub(crate) last: zenoh::pubsub::Publisher<'static>,
}

impl CmdPublisher {
    /// Both publishers on `key`.
    fn declare(session: &zenoh::Session, key: String) -> Result<CmdPublisher, FleetError> {
        let declare = |congestion| {
            session
                .declare_publisher(key.clone())
                .congestion_control(congestion)
                .wait()
                .map_err(|e| FleetError::Zenoh(format!("declaring {key}: {e}")))
        };
        Ok(CmdPublisher {
            each: declare(CongestionControl::Drop)?,
            last: declare(CongestionControl::Block)?,
        })
    }
}

/// `cmd_vel` through a robot's [`CmdPublisher`], stamped by the system
/// clock.
pub(crate) struct OwnedCmdSink(pub(crate) CmdPublisher);

impl std::fmt::Debug for OwnedCmdSink {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("OwnedCmdSink")
    }
}

fn put(
    publisher: &zenoh::pubsub::Publisher<'_>,
    payload: &[u8],
    attachment: &[u8],
) -> Result<(), String> {
    publisher
        .put(payload.to_vec())
        .attachment(attachment.to_vec())
        .wait()
        .map_err(|e| e.to_string())
}

impl CmdSink for OwnedCmdSink {
    fn now_ns(&self) -> i64 {
        crate::unix_nanos() as i64
    }
    fn reader_present(&self) -> Option<bool> {
        self.0
            .each
            .matching_status()
            .wait()
            .ok()
            .map(|m| m.matching())
    }
    fn send(&mut self, payload: &[u8], attachment: &[u8]) -> Result<(), String> {
        put(&self.0.each, payload, attachment)
    }
    /// Blocks (at most Zenoh's `wait_before_close`, 5 s, on a queue that
    /// does not move) only off Zenoh's runtime: the process's last words
    /// are said on its own thread ([`crate::runtime::run_split`]), where
    /// waiting for the queue cannot stall Zenoh's transmission. A stop ticked
    /// on Zenoh's thread (the leader or the odometry lost mid-run) goes out
    /// as every command does, never blocking there; the robot commands zero
    /// again at each tick while it stays stopped.
    fn send_stop(&mut self, payload: &[u8], attachment: &[u8]) -> Result<(), String> {
        let off_zenoh = tokio::runtime::Handle::try_current().is_err();
        let publisher = if off_zenoh {
            &self.0.last
        } else {
            &self.0.each
        };
        put(publisher, payload, attachment)
    }
}
