//! rmw_zenoh liveliness tokens: how `ros2 node list` and `ros2 topic list`
//! on a ROS 2 machine learn of a node, its publishers and its subscriptions.
//!
//! The format is rmw_zenoh Jazzy 0.2.x's (`liveliness_utils.cpp`, `Entity`;
//! on Humble, [`NodeInfo::with_scheme`], `TypeHashNotSupported` stands for the
//! hash):
//!
//! ```text
//! @ros2_lv/<domain>/<zid>/<node id>/<entity id>/<NN|MP|MS>/<enclave>/<namespace>/<node name>
//!     [/<topic>/<DDS type name>/<RIHS01 hash>/<qos>]
//! ```
//!
//! `<zid>` is the Zenoh session id as Zenoh prints it; a node's entity id is
//! its node id; ids come from one counter per Zenoh session. Names are
//! "mangled": every `/` becomes `%`, so the root namespace `/` is `%` and the
//! topic `/robot1/cmd_vel` is `%robot1%cmd_vel`. The QoS field is
//! `reliability:durability:history,depth:deadline s,ns:lifespan s,ns:liveliness,lease s,ns`,
//! each number written only when it differs from rmw_zenoh's default
//! ([`Qos::default`]), enum values as `rmw/types.h` numbers them.

use std::time::Duration;

use crate::keys::hash_chunk;
use crate::msgs::MessageType;
use crate::names::{KeyScheme, NameError, check_node_name, normalize_namespace};

/// The key prefix of every rmw_zenoh liveliness token.
pub const ADMIN_SPACE: &str = "@ros2_lv";

/// QoS reliability.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Reliability {
    /// `RMW_QOS_POLICY_RELIABILITY_RELIABLE` (1), rmw_zenoh's default.
    #[default]
    Reliable,
    /// `RMW_QOS_POLICY_RELIABILITY_BEST_EFFORT` (2).
    BestEffort,
}

/// QoS durability.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Durability {
    /// `RMW_QOS_POLICY_DURABILITY_TRANSIENT_LOCAL` (1).
    TransientLocal,
    /// `RMW_QOS_POLICY_DURABILITY_VOLATILE` (2), rmw_zenoh's default.
    #[default]
    Volatile,
}

/// QoS history.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum History {
    /// `KEEP_LAST` (1) with a depth; depth 0 means rmw_zenoh's default 42.
    KeepLast(u32),
    /// `KEEP_ALL` (2).
    KeepAll,
}

impl Default for History {
    fn default() -> History {
        History::KeepLast(DEFAULT_DEPTH)
    }
}

/// QoS liveliness.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Liveliness {
    /// `RMW_QOS_POLICY_LIVELINESS_AUTOMATIC` (1), rmw_zenoh's default.
    #[default]
    Automatic,
    /// `RMW_QOS_POLICY_LIVELINESS_MANUAL_BY_TOPIC` (3).
    ManualByTopic,
}

/// rmw_zenoh's history depth when none is given.
pub const DEFAULT_DEPTH: u32 = 42;

/// A QoS profile as rmw_zenoh advertises it (after its "best available"
/// adaptation: no system defaults). `None` durations are infinite.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Qos {
    /// Reliability.
    pub reliability: Reliability,
    /// Durability.
    pub durability: Durability,
    /// History and depth.
    pub history: History,
    /// Deadline (`None` or zero: infinite).
    pub deadline: Option<Duration>,
    /// Lifespan (`None` or zero: infinite).
    pub lifespan: Option<Duration>,
    /// Liveliness kind.
    pub liveliness: Liveliness,
    /// Liveliness lease (`None` or zero: infinite).
    pub liveliness_lease: Option<Duration>,
}

impl Qos {
    /// rclcpp's `QoS(depth)`: reliable, volatile, keep last `depth` (what
    /// `ros2 topic pub` and most nodes use; `depth` 10 encodes as `::,10:,:,:,,`).
    pub fn keep_last(depth: u32) -> Qos {
        Qos {
            history: History::KeepLast(depth),
            ..Qos::default()
        }
    }
}

/// `RMW_DURATION_INFINITE` as `rmw_time_t` {sec, nsec}.
const INFINITE: (u64, u64) = (9_223_372_036, 854_775_807);

/// A QoS duration as rmw's `rmw_time_t` {sec, nsec}: `None` and zero are
/// infinite (`RMW_DURATION_INFINITE`).
pub fn rmw_time(d: Option<Duration>) -> (u64, u64) {
    match d {
        Some(d) if !d.is_zero() => (d.as_secs(), u64::from(d.subsec_nanos())),
        _ => INFINITE,
    }
}

fn push_if(out: &mut String, value: u64, default: u64) {
    if value != default {
        out.push_str(&value.to_string());
    }
}

fn push_duration(out: &mut String, d: Option<Duration>) {
    let (s, ns) = rmw_time(d);
    push_if(out, s, INFINITE.0);
    out.push(',');
    push_if(out, ns, INFINITE.1);
}

/// The QoS field of a token, exactly as rmw_zenoh's `qos_to_keyexpr` writes it.
pub fn qos_keyexpr(qos: &Qos) -> String {
    let mut out = String::new();
    if qos.reliability == Reliability::BestEffort {
        out.push('2');
    }
    out.push(':');
    if qos.durability == Durability::TransientLocal {
        out.push('1');
    }
    out.push(':');
    let depth = match qos.history {
        History::KeepLast(depth) => depth,
        History::KeepAll => {
            out.push('2');
            0
        }
    };
    out.push(',');
    // rmw_zenoh replaces depth 0 by its default before writing the token.
    let depth = if depth == 0 { DEFAULT_DEPTH } else { depth };
    push_if(&mut out, u64::from(depth), u64::from(DEFAULT_DEPTH));
    out.push(':');
    push_duration(&mut out, qos.deadline);
    out.push(':');
    push_duration(&mut out, qos.lifespan);
    out.push(':');
    if qos.liveliness == Liveliness::ManualByTopic {
        out.push('3');
    }
    out.push(',');
    push_duration(&mut out, qos.liveliness_lease);
    out
}

/// A name as it appears in a token: `/` becomes `%`; an empty name is `%`.
pub fn mangle(name: &str) -> String {
    if name.is_empty() {
        return "%".to_owned();
    }
    name.replace('/', "%")
}

/// What kind of endpoint a token declares.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Endpoint {
    /// A publisher (`MP`).
    Publisher,
    /// A subscription (`MS`).
    Subscription,
}

impl Endpoint {
    /// Its entity kind in a token.
    fn code(self) -> &'static str {
        match self {
            Endpoint::Publisher => "MP",
            Endpoint::Subscription => "MS",
        }
    }
}

/// The ROS 2 node echelon appears as.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct NodeInfo {
    /// `ROS_DOMAIN_ID`.
    pub domain_id: u32,
    /// The Zenoh session id, as `session.zid().to_string()` prints it.
    pub zid: String,
    /// The node's entity id (unique in the session; rmw_zenoh counts from 0).
    pub node_id: u64,
    /// The security enclave, `/` by default.
    pub enclave: String,
    /// The node namespace, canonical (`/` or `/robot1`).
    pub namespace: String,
    /// The node name.
    pub name: String,
    /// How the type hash is written in its endpoints' tokens (rmw_zenoh on
    /// Jazzy by default, [`KeyScheme::RmwZenohHumble`] on Humble).
    pub scheme: KeyScheme,
}

impl NodeInfo {
    /// A node in `namespace` (any form [`normalize_namespace`] takes) with
    /// the default enclave `/`; the name and namespace are validated.
    pub fn new(
        domain_id: u32,
        zid: &str,
        node_id: u64,
        namespace: &str,
        name: &str,
    ) -> Result<NodeInfo, NameError> {
        check_node_name(name)?;
        Ok(NodeInfo {
            domain_id,
            zid: zid.to_owned(),
            node_id,
            enclave: "/".to_owned(),
            namespace: normalize_namespace(namespace)?,
            name: name.to_owned(),
            scheme: KeyScheme::RmwZenoh,
        })
    }

    /// The node as a robot of key scheme `scheme` sees it (Humble's tokens
    /// carry `TypeHashNotSupported`; the bridge's keys carry no tokens of
    /// echelon's, so it keeps Jazzy's form).
    pub fn with_scheme(self, scheme: KeyScheme) -> NodeInfo {
        NodeInfo { scheme, ..self }
    }

    fn prefix(&self, entity_id: u64, kind: &str) -> String {
        format!(
            "{ADMIN_SPACE}/{}/{}/{}/{entity_id}/{kind}/{}/{}/{}",
            self.domain_id,
            self.zid,
            self.node_id,
            mangle(&self.enclave),
            mangle(&self.namespace),
            mangle(&self.name)
        )
    }

    /// A publisher's (`MP`) or a subscription's (`MS`) token for fully
    /// qualified topic `fq_topic`.
    pub fn endpoint_token(
        &self,
        kind: Endpoint,
        entity_id: u64,
        fq_topic: &str,
        ty: &MessageType,
        qos: &Qos,
    ) -> String {
        format!(
            "{}/{}/{}/{}/{}",
            self.prefix(entity_id, kind.code()),
            mangle(fq_topic),
            mangle(&ty.dds_name()),
            mangle(hash_chunk(self.scheme, ty).unwrap_or(ty.hash)),
            qos_keyexpr(qos)
        )
    }

    /// The node's token (`NN`).
    pub fn node_token(&self) -> String {
        self.prefix(self.node_id, "NN")
    }
}

/// The key that matches every token of `domain_id` (for a liveliness
/// subscriber or query, as rmw_zenoh's graph cache uses).
pub fn domain_tokens(domain_id: u32) -> String {
    format!("{ADMIN_SPACE}/{domain_id}/**")
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::msgs::{ODOMETRY, TWIST_STAMPED};

    #[test]
    fn qos_strings_match_rmw_zenoh() {
        // rclcpp::SystemDefaultsQoS() (diff_drive_controller's cmd_vel and odom):
        // everything adapts to rmw_zenoh's defaults.
        assert_eq!(qos_keyexpr(&Qos::default()), "::,:,:,:,,");
        assert_eq!(qos_keyexpr(&Qos::keep_last(0)), "::,:,:,:,,");
        assert_eq!(qos_keyexpr(&Qos::keep_last(10)), "::,10:,:,:,,");
        // rclcpp::SensorDataQoS(): best effort, keep last 5.
        let sensor = Qos {
            reliability: Reliability::BestEffort,
            history: History::KeepLast(5),
            ..Qos::default()
        };
        assert_eq!(qos_keyexpr(&sensor), "2::,5:,:,:,,");
        let everything = Qos {
            reliability: Reliability::BestEffort,
            durability: Durability::TransientLocal,
            history: History::KeepAll,
            deadline: Some(Duration::from_millis(1500)),
            lifespan: Some(Duration::from_secs(2)),
            liveliness: Liveliness::ManualByTopic,
            liveliness_lease: Some(Duration::from_nanos(7)),
        };
        assert_eq!(qos_keyexpr(&everything), "2:1:2,:1,500000000:2,0:3,0,7");
    }

    #[test]
    fn tokens_have_rmw_zenohs_layout() {
        let node = NodeInfo::new(0, "c0ffee", 0, "robot1", "echelon_robot").expect("valid");
        assert_eq!(node.namespace, "/robot1");
        assert_eq!(
            node.node_token(),
            "@ros2_lv/0/c0ffee/0/0/NN/%/%robot1/echelon_robot"
        );
        // The same publisher on Jazzy's keys and on Humble's (below).
        let cmd_vel = |n: &NodeInfo| {
            n.endpoint_token(
                Endpoint::Publisher,
                1,
                "/robot1/cmd_vel",
                &TWIST_STAMPED,
                &Qos::keep_last(10),
            )
        };
        assert_eq!(
            cmd_vel(&node),
            "@ros2_lv/0/c0ffee/0/1/MP/%/%robot1/echelon_robot/%robot1%cmd_vel/\
             geometry_msgs::msg::dds_::TwistStamped_/\
             RIHS01_5f0fcd4f81d5d06ad9b4c4c63e3ea51b82d6ae4d0558f1d475229b1121db6f64/::,10:,:,:,,"
        );
        assert_eq!(
            node.endpoint_token(
                Endpoint::Subscription,
                2,
                "/robot1/odom",
                &ODOMETRY,
                &Qos::default()
            ),
            "@ros2_lv/0/c0ffee/0/2/MS/%/%robot1/echelon_robot/%robot1%odom/\
             nav_msgs::msg::dds_::Odometry_/\
             RIHS01_3cc97dc7fb7502f8714462c526d369e35b603cfc34d946e3f2eda2766dfec6e0/::,:,:,:,,"
        );
        // On Humble the hash's chunk is `TypeHashNotSupported`; the node's
        // own token has no type and does not change.
        let humble = node.clone().with_scheme(KeyScheme::RmwZenohHumble);
        assert_eq!(humble.node_token(), node.node_token());
        assert_eq!(
            cmd_vel(&humble),
            "@ros2_lv/0/c0ffee/0/1/MP/%/%robot1/echelon_robot/%robot1%cmd_vel/\
             geometry_msgs::msg::dds_::TwistStamped_/TypeHashNotSupported/::,10:,:,:,,"
        );
        let root = NodeInfo::new(7, "ab", 3, "", "n").expect("valid");
        assert_eq!(root.node_token(), "@ros2_lv/7/ab/3/3/NN/%/%/n");
        assert_eq!(domain_tokens(7), "@ros2_lv/7/**");
        assert!(NodeInfo::new(0, "ab", 0, "/", "bad/name").is_err());
        assert!(NodeInfo::new(0, "ab", 0, "/a//b", "n").is_err());
    }
}
