//! A fleet process's ROS 2 presence (the robot's and `fleet excite`'s): a
//! node with a `cmd_vel` publisher and an `odom` subscription, as rmw_zenoh
//! declares them, and `cmd_vel` sent through Zenoh.

use std::sync::mpsc;
use std::time::Instant;

use zenoh::Wait;

use echelon::scenario::Ros2Link;

use crate::FleetError;
use crate::ros2::declare_tokens;
use crate::ros2::drive::{CmdSink, cmd_vel_type};
use echelon_ros2::attachment::{Gid, gid_from_token};
use echelon_ros2::keys::{topic_key, topic_key_any_type};
use echelon_ros2::liveliness::{NodeInfo, Qos};
use echelon_ros2::msgs::ODOMETRY;

/// Agent `k`'s ROS 2 presence: a node `<namespace>/echelon_robot` with a
/// `cmd_vel` publisher and an `odom` subscription, as rmw_zenoh declares
/// them (liveliness tokens), and the odometry that arrives.
pub(crate) struct Ros2Endpoint<'a> {
    pub(crate) publisher: zenoh::pubsub::Publisher<'a>,
    pub(crate) gid: Gid,
    pub(crate) odom: mpsc::Receiver<(Instant, String, Vec<u8>)>,
    _subscriber: zenoh::pubsub::Subscriber<()>,
    _tokens: Vec<zenoh::liveliness::LivelinessToken>,
}

impl<'a> Ros2Endpoint<'a> {
    pub(crate) fn declare(
        session: &'a zenoh::Session,
        link: &Ros2Link,
        agent: u32,
    ) -> Result<Ros2Endpoint<'a>, FleetError> {
        let zid = session.zid().to_string();
        let node = NodeInfo::new(link.domain_id, &zid, 0, &link.namespace, "echelon_robot")
            .map_err(|e| FleetError::Config(format!("agent {agent}: {e}")))?
            .with_scheme(link.key_scheme);
        let cmd_type = cmd_vel_type(link);
        let pub_token = node.publisher_token(1, &link.cmd_vel, &cmd_type, &Qos::default());
        let tokens = declare_tokens(
            session,
            &[
                node.node_token(),
                pub_token.clone(),
                node.subscription_token(2, &link.odom, &ODOMETRY, &Qos::default()),
            ],
        )?;
        let (tx, odom) = mpsc::channel();
        // Any type on the odom topic, so a publisher of the wrong type is
        // seen, counted and refused rather than never heard.
        let odom_key = topic_key_any_type(link.key_scheme, link.domain_id, &link.odom);
        let subscriber = session
            .declare_subscriber(&odom_key)
            .callback(move |s| {
                let _ = tx.send((
                    Instant::now(),
                    s.key_expr().as_str().to_owned(),
                    s.payload().to_bytes().into_owned(),
                ));
            })
            .wait()
            .map_err(|e| FleetError::Zenoh(format!("subscribing to {odom_key}: {e}")))?;
        let cmd_key = topic_key(link.key_scheme, link.domain_id, &link.cmd_vel, &cmd_type);
        let publisher = session
            .declare_publisher(cmd_key.clone())
            .wait()
            .map_err(|e| FleetError::Zenoh(format!("declaring {cmd_key}: {e}")))?;
        Ok(Ros2Endpoint {
            publisher,
            gid: gid_from_token(&pub_token),
            odom,
            _subscriber: subscriber,
            _tokens: tokens,
        })
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
