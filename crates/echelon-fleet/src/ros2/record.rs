//! Recording ROS 2 topics as `ros2 bag record -s mcap` does: which topics
//! the fleet collector listens to ([`RosTopic`]), how a received sample is
//! checked before it is recorded as its topic's type ([`RosTopic::check`]),
//! and what rosbag2 writes about a topic in an MCAP file (the
//! [`Ros2Schema`] with the full definition from [`echelon_ros2::definitions`], and
//! the `offered_qos_profiles` YAML of [`offered_qos_profiles`]).
//!
//! The collector records the bytes as they were received; it decodes them
//! only to refuse what is not a valid CDR message of the topic's type.
//! Non-finite numbers are recorded: the log shows what was sent (the robot is
//! the one that refuses them).

use echelon_mcap::Ros2Schema;

use echelon_ros2::attachment::Attachment;
use echelon_ros2::cdr::CdrError;
use echelon_ros2::definitions::definition;
use echelon_ros2::keys::{KeyMismatch, check_topic_key, topic_key_any_type};
use echelon_ros2::liveliness::{Durability, History, Liveliness, Qos, Reliability, rmw_time};
use echelon_ros2::msgs::{
    MessageType, ODOMETRY, Odometry, RosMessage, TWIST, TWIST_STAMPED, Twist, TwistStamped,
};
use echelon_ros2::names::{KeyScheme, NameError, fully_qualified_topic};

/// A ROS 2 topic the fleet collector records into `fleet.mcap`, on a channel
/// named by its fully qualified name (`/robot1/cmd_vel`).
///
/// Build one per topic with [`RosTopic::new`] (e.g. for every robot its
/// `cmd_vel` of type [`TWIST_STAMPED`] or [`TWIST`] and its `odom` of type
/// [`ODOMETRY`]); [`RosTopic::key_expr`] is the Zenoh key to subscribe to.
#[derive(Debug, Clone, PartialEq)]
pub struct RosTopic {
    topic: String,
    msg: MessageType,
    scheme: KeyScheme,
    domain_id: u32,
    /// `<domain>/<topic without the leading slash>` (rmw_zenoh) or the topic
    /// without the leading slash (bridge): what a sample key starts with.
    key_topic: String,
    qos: Qos,
    qos_yaml: String,
}

/// A topic the collector cannot record.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum RosTopicError {
    /// Not a valid ROS name.
    #[error(transparent)]
    Name(#[from] NameError),
    /// A type whose message definition echelon does not carry.
    #[error(
        "ROS topic `{topic}`: type `{ty}` cannot be recorded (echelon records geometry_msgs/msg/Twist, TwistStamped, PoseStamped, PoseWithCovarianceStamped and nav_msgs/msg/Odometry)"
    )]
    UnsupportedType {
        /// The topic.
        topic: String,
        /// The type name.
        ty: &'static str,
    },
    /// The same topic given twice.
    #[error("ROS topic `{0}` is listed twice")]
    Duplicate(String),
    /// A topic whose MCAP channel name is one of echelon's own channels.
    #[error("ROS topic `{0}` has the name of one of echelon's channels in fleet.mcap")]
    Reserved(String),
}

/// Why a sample was not recorded as its topic's type: the reason the
/// collector counts and logs it under on `/rejected`.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum RosRefusal {
    /// The key names another message type or type hash.
    #[error(transparent)]
    Key(#[from] KeyMismatch),
    /// The payload is not a valid CDR message of the topic's type.
    #[error("{0}")]
    Cdr(#[from] CdrError),
}

impl RosRefusal {
    /// A short, stable reason for counting (no values in it).
    pub fn reason(&self) -> &'static str {
        match self {
            RosRefusal::Key(KeyMismatch::NotATopicKey(_)) => "ROS: not a topic key",
            RosRefusal::Key(KeyMismatch::WrongType { .. }) => "ROS: wrong message type on the key",
            RosRefusal::Key(KeyMismatch::WrongHash { .. }) => "ROS: wrong type hash on the key",
            RosRefusal::Cdr(CdrError::WrongEncapsulation { .. }) => "ROS: not CDR little-endian",
            RosRefusal::Cdr(_) => "ROS: malformed CDR for the topic's type",
        }
    }
}

impl RosTopic {
    /// The topic `topic` in `namespace` (ROS rules: an absolute `topic`
    /// ignores the namespace) carrying `msg`, under key scheme `scheme` in
    /// ROS domain `domain_id` (unused by the bridge scheme). The offered QoS
    /// recorded is rmw_zenoh's default ([`Qos::default`]); see
    /// [`RosTopic::with_qos`].
    pub fn new(
        scheme: KeyScheme,
        domain_id: u32,
        namespace: &str,
        topic: &str,
        msg: MessageType,
    ) -> Result<RosTopic, RosTopicError> {
        let topic = fully_qualified_topic(namespace, topic)?;
        if definition(&msg).is_none() {
            return Err(RosTopicError::UnsupportedType {
                topic,
                ty: msg.name,
            });
        }
        let trimmed = topic.trim_start_matches('/');
        let key_topic = match scheme {
            KeyScheme::RmwZenoh | KeyScheme::RmwZenohHumble => format!("{domain_id}/{trimmed}"),
            KeyScheme::Bridge => trimmed.to_owned(),
        };
        let qos = Qos::default();
        Ok(RosTopic {
            topic,
            msg,
            scheme,
            domain_id,
            key_topic,
            qos,
            qos_yaml: offered_qos_profiles(&[qos]),
        })
    }

    /// A robot's two topics in `namespace`: `cmd_vel` of type `cmd_vel`
    /// ([`TWIST_STAMPED`] or [`TWIST`]) and `odom` of type [`ODOMETRY`].
    pub fn robot(
        scheme: KeyScheme,
        domain_id: u32,
        namespace: &str,
        cmd_vel: MessageType,
    ) -> Result<[RosTopic; 2], RosTopicError> {
        Ok([
            RosTopic::new(scheme, domain_id, namespace, "cmd_vel", cmd_vel)?,
            RosTopic::new(scheme, domain_id, namespace, "odom", ODOMETRY)?,
        ])
    }

    /// The `cmd_vel` and `odom` topics of an agent's resolved `[fleet.ros2]`
    /// link (its own topic names, types and key scheme).
    pub fn of_link(link: &echelon::scenario::Ros2Link) -> Result<[RosTopic; 2], RosTopicError> {
        let topic = |name: &str, ty| {
            RosTopic::new(link.key_scheme, link.domain_id, &link.namespace, name, ty)
        };
        Ok([
            topic(&link.cmd_vel, *super::drive::cmd_vel_type(link))?,
            topic(&link.odom, ODOMETRY)?,
        ])
    }

    /// [`RosTopic::of_link`]'s, the ground truth a simulated base publishes
    /// ([`super::ground_truth_topic`]) and the agent's fixes, if it
    /// takes any from ROS 2: what `fleet collect --ros2` records.
    pub fn all_of_link(link: &echelon::scenario::Ros2Link) -> Result<Vec<RosTopic>, RosTopicError> {
        let topic = |name: &str, ty| {
            RosTopic::new(link.key_scheme, link.domain_id, &link.namespace, name, ty)
        };
        let mut topics = Vec::from(RosTopic::of_link(link)?);
        topics.push(topic(&super::ground_truth_topic(link), ODOMETRY)?);
        if let Some(f) = &link.fixes {
            topics.push(topic(&f.topic, *super::fixes::fix_type(f.message))?);
        }
        Ok(topics)
    }

    /// The same topic, its publishers offering `qos` (recorded as the
    /// channel's `offered_qos_profiles`).
    pub fn with_qos(mut self, qos: Qos) -> RosTopic {
        self.qos = qos;
        self.qos_yaml = offered_qos_profiles(&[qos]);
        self
    }

    /// Fully qualified topic name: the MCAP channel's topic.
    pub fn topic(&self) -> &str {
        &self.topic
    }

    /// The message type recorded.
    pub fn msg(&self) -> MessageType {
        self.msg
    }

    /// The key scheme.
    pub fn scheme(&self) -> KeyScheme {
        self.scheme
    }

    /// The ROS domain id.
    pub fn domain_id(&self) -> u32 {
        self.domain_id
    }

    /// The QoS recorded as offered.
    pub fn qos(&self) -> Qos {
        self.qos
    }

    /// The Zenoh key expression to subscribe to: the topic with any type
    /// (`<domain>/<topic>/*/*` for rmw_zenoh), so that a publisher of
    /// another type is seen and refused rather than never heard.
    pub fn key_expr(&self) -> String {
        topic_key_any_type(self.scheme, self.domain_id, &self.topic)
    }

    /// Whether a sample key belongs to this topic, whatever type it names:
    /// for rmw_zenoh `<domain>/<topic>/<type>/<hash>`, for the bridge the
    /// topic itself.
    pub fn owns(&self, key: &str) -> bool {
        match self.scheme {
            KeyScheme::Bridge => key == self.key_topic,
            KeyScheme::RmwZenoh | KeyScheme::RmwZenohHumble => key
                .strip_prefix(self.key_topic.as_str())
                .and_then(|rest| rest.strip_prefix('/'))
                .is_some_and(|rest| {
                    let mut chunks = rest.split('/');
                    matches!(
                        (chunks.next(), chunks.next(), chunks.next()),
                        (Some(_), Some(_), None)
                    )
                }),
        }
    }

    /// Checks a sample of this topic received on `key`: the key names the
    /// topic's type and hash, and the payload is a valid CDR message of the
    /// type (non-finite numbers are accepted).
    pub fn check(&self, key: &str, payload: &[u8]) -> Result<(), RosRefusal> {
        check_topic_key(self.scheme, key, &self.msg)?;
        let decoded = match self.msg.name {
            n if n == TWIST.name => Twist::from_cdr(payload).map(drop),
            n if n == TWIST_STAMPED.name => TwistStamped::from_cdr(payload).map(drop),
            n if n == ODOMETRY.name => Odometry::from_cdr(payload).map(drop),
            // `new` refuses every other type.
            _ => Ok(()),
        };
        decoded.map_err(RosRefusal::from)
    }

    /// The MCAP schema of the topic's type.
    pub fn schema(&self) -> Ros2Schema {
        Ros2Schema {
            name: self.msg.name,
            definition: definition(&self.msg).unwrap_or_default(),
            type_hash: self.msg.hash,
        }
    }

    /// The channel's `offered_qos_profiles` metadata (see [`offered_qos_profiles`]).
    pub fn offered_qos_profiles(&self) -> &str {
        &self.qos_yaml
    }
}

/// The publication time of a sample: the source timestamp of its rmw_zenoh
/// attachment (UNIX ns) when there is a valid one with a positive time,
/// else `received` (the receipt time, as rosbag2 does without one).
pub fn publish_time(attachment: Option<&[u8]>, received: u64) -> u64 {
    attachment
        .and_then(|a| Attachment::decode(a).ok())
        .and_then(|a| u64::try_from(a.source_timestamp_ns).ok())
        .filter(|&t| t > 0)
        .unwrap_or(received)
}

/// Checks a list of topics for the collector: no topic twice, none named
/// like one of echelon's own channels (`/reference`, `/rejected`,
/// `/agent/…`).
pub fn check_topics(topics: &[RosTopic]) -> Result<(), RosTopicError> {
    for (i, t) in topics.iter().enumerate() {
        if topics[..i].iter().any(|o| o.topic == t.topic) {
            return Err(RosTopicError::Duplicate(t.topic.clone()));
        }
        if t.topic == "/reference" || t.topic == "/rejected" || t.topic.starts_with("/agent/") {
            return Err(RosTopicError::Reserved(t.topic.clone()));
        }
    }
    Ok(())
}

/// rosbag2's `offered_qos_profiles` channel metadata: the YAML list of QoS
/// profiles rosbag2 (Jazzy, metadata version 9) writes with yaml-cpp, policy
/// names as `rmw_qos_*_policy_to_str` spells them, infinite durations as
/// `RMW_DURATION_INFINITE` (`sec: 9223372036`, `nsec: 854775807`); `[]` for
/// none.
pub fn offered_qos_profiles(profiles: &[Qos]) -> String {
    use std::fmt::Write as _;
    if profiles.is_empty() {
        return "[]".to_owned();
    }
    let mut out = String::new();
    let time = |out: &mut String, name: &str, d| {
        let (sec, nsec) = rmw_time(d);
        let _ = write!(out, "\n  {name}:\n    sec: {sec}\n    nsec: {nsec}");
    };
    for (i, q) in profiles.iter().enumerate() {
        if i > 0 {
            out.push('\n');
        }
        let (history, depth) = match q.history {
            History::KeepLast(d) => ("keep_last", d),
            History::KeepAll => ("keep_all", 0),
        };
        let reliability = match q.reliability {
            Reliability::Reliable => "reliable",
            Reliability::BestEffort => "best_effort",
        };
        let durability = match q.durability {
            Durability::Volatile => "volatile",
            Durability::TransientLocal => "transient_local",
        };
        let liveliness = match q.liveliness {
            Liveliness::Automatic => "automatic",
            Liveliness::ManualByTopic => "manual_by_topic",
        };
        let _ = write!(
            out,
            "- history: {history}\n  depth: {depth}\n  reliability: {reliability}\n  durability: {durability}"
        );
        time(&mut out, "deadline", q.deadline);
        time(&mut out, "lifespan", q.lifespan);
        let _ = write!(out, "\n  liveliness: {liveliness}");
        time(&mut out, "liveliness_lease_duration", q.liveliness_lease);
        out.push_str("\n  avoid_ros_namespace_conventions: false");
    }
    out
}

#[cfg(test)]
mod tests {
    use std::time::Duration;

    use super::*;
    use echelon_ros2::keys::topic_key;
    use echelon_ros2::msgs::{HEADER, Time};

    fn cmd_vel() -> RosTopic {
        RosTopic::new(KeyScheme::RmwZenoh, 0, "/robot1", "cmd_vel", TWIST_STAMPED).expect("valid")
    }

    #[test]
    fn a_topic_owns_its_keys_of_any_type_and_no_other() {
        let t = cmd_vel();
        assert_eq!(t.topic(), "/robot1/cmd_vel");
        assert_eq!(t.key_expr(), "0/robot1/cmd_vel/*/*");
        let key = topic_key(KeyScheme::RmwZenoh, 0, "/robot1/cmd_vel", &TWIST_STAMPED);
        assert!(t.owns(&key));
        assert!(t.owns(&topic_key(
            KeyScheme::RmwZenoh,
            0,
            "/robot1/cmd_vel",
            &TWIST
        )));
        for other in [
            topic_key(KeyScheme::RmwZenoh, 1, "/robot1/cmd_vel", &TWIST_STAMPED),
            topic_key(KeyScheme::RmwZenoh, 0, "/robot1/cmd_vel_x", &TWIST_STAMPED),
            topic_key(KeyScheme::RmwZenoh, 0, "/robot1/cmd_vel/x", &TWIST_STAMPED),
            topic_key(KeyScheme::RmwZenoh, 0, "/robot10/cmd_vel", &TWIST_STAMPED),
            "0/robot1/cmd_vel".to_owned(),
            "0/robot1/cmd_vel/a".to_owned(),
            String::new(),
        ] {
            assert!(!t.owns(&other), "{other}");
        }
        let b = RosTopic::new(KeyScheme::Bridge, 7, "robot1", "odom", ODOMETRY).expect("valid");
        assert_eq!(b.key_expr(), "robot1/odom");
        assert!(b.owns("robot1/odom"));
        assert!(!b.owns("robot1/odom/x"));
    }

    #[test]
    fn samples_of_the_wrong_type_or_bad_cdr_are_refused_with_a_reason() {
        let t = cmd_vel();
        let key = topic_key(KeyScheme::RmwZenoh, 0, "/robot1/cmd_vel", &TWIST_STAMPED);
        let good = TwistStamped::planar(0.5, -0.2, Time::from_nanos(7), "base_link").to_cdr();
        assert_eq!(t.check(&key, &good), Ok(()));
        let nan = TwistStamped::planar(f64::NAN, 0.0, Time::default(), "").to_cdr();
        assert_eq!(t.check(&key, &nan), Ok(()), "recorded as sent");
        let reason = |k: &str, p: &[u8]| t.check(k, p).map_err(|e| e.reason());
        let twist_key = topic_key(KeyScheme::RmwZenoh, 0, "/robot1/cmd_vel", &TWIST);
        assert_eq!(
            reason(&twist_key, &Twist::planar(1.0, 0.0).to_cdr()),
            Err("ROS: wrong message type on the key")
        );
        let other_hash = format!("0/robot1/cmd_vel/{}/RIHS01_00", TWIST_STAMPED.dds_name());
        assert_eq!(
            reason(&other_hash, &good),
            Err("ROS: wrong type hash on the key")
        );
        assert_eq!(
            reason(&key, &good[..good.len() - 1]),
            Err("ROS: malformed CDR for the topic's type")
        );
        let mut big_endian = good.clone();
        big_endian[1] = 0;
        assert_eq!(reason(&key, &big_endian), Err("ROS: not CDR little-endian"));
        assert!(matches!(
            RosTopic::new(KeyScheme::RmwZenoh, 0, "/r", "header", HEADER),
            Err(RosTopicError::UnsupportedType { .. })
        ));
        assert!(matches!(
            RosTopic::new(KeyScheme::RmwZenoh, 0, "/r", "~/odom", ODOMETRY),
            Err(RosTopicError::Name(_))
        ));
    }

    #[test]
    fn topic_lists_are_checked() {
        let [c, o] = RosTopic::robot(KeyScheme::RmwZenoh, 0, "robot1", TWIST).expect("valid");
        assert_eq!((c.topic(), o.topic()), ("/robot1/cmd_vel", "/robot1/odom"));
        assert_eq!(check_topics(&[c.clone(), o]), Ok(()));
        assert_eq!(
            check_topics(&[c.clone(), c]),
            Err(RosTopicError::Duplicate("/robot1/cmd_vel".to_owned()))
        );
        let reserved =
            RosTopic::new(KeyScheme::RmwZenoh, 0, "/", "rejected", TWIST).expect("valid");
        assert!(matches!(
            check_topics(&[reserved]),
            Err(RosTopicError::Reserved(_))
        ));
    }

    #[test]
    fn publish_time_is_the_attachment_source_timestamp() {
        let a = Attachment {
            sequence_number: 1,
            source_timestamp_ns: 1_700_000_000_000_000_001,
            gid: [3; 16],
        };
        assert_eq!(
            publish_time(Some(&a.encode()), 9),
            1_700_000_000_000_000_001
        );
        assert_eq!(publish_time(None, 9), 9);
        assert_eq!(publish_time(Some(&[1, 2, 3]), 9), 9);
        let negative = Attachment {
            source_timestamp_ns: -5,
            ..a
        };
        assert_eq!(publish_time(Some(&negative.encode()), 9), 9);
    }

    #[test]
    fn qos_profiles_are_written_as_rosbag2_yaml() {
        let infinite = "    sec: 9223372036\n    nsec: 854775807";
        assert_eq!(
            offered_qos_profiles(&[Qos::keep_last(10)]),
            format!(
                "- history: keep_last\n  depth: 10\n  reliability: reliable\n  durability: volatile\n  \
                 deadline:\n{infinite}\n  lifespan:\n{infinite}\n  liveliness: automatic\n  \
                 liveliness_lease_duration:\n{infinite}\n  avoid_ros_namespace_conventions: false"
            )
        );
        let q = Qos {
            reliability: Reliability::BestEffort,
            durability: Durability::TransientLocal,
            history: History::KeepAll,
            deadline: Some(Duration::from_millis(1500)),
            ..Qos::default()
        };
        let two = offered_qos_profiles(&[q, Qos::default()]);
        assert!(two.starts_with(
            "- history: keep_all\n  depth: 0\n  reliability: best_effort\n  durability: transient_local\n  \
             deadline:\n    sec: 1\n    nsec: 500000000\n"
        ));
        assert_eq!(
            two.matches("\n- history: keep_last\n  depth: 42\n").count(),
            1
        );
        assert_eq!(offered_qos_profiles(&[]), "[]");
    }
}
