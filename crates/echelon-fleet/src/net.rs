//! Zenoh sessions: the default configuration (peer mode, no multicast
//! scouting, explicit endpoints), client mode (one link to a router), router
//! mode (`fleet router`), a user's `--zenoh-config` file, and the secure mode
//! (mutual TLS with access control by certificate common name). Every
//! process's session, the router's included, is configured here.

use std::path::{Path, PathBuf};

use serde::Serialize;
use serde_json::json;
use zenoh::bytes::ZBytes;
use zenoh::{Config, Session, Wait};

use crate::FleetError;
use crate::keys::{Keys, every_fleet};
use crate::role::Member;

/// How long `open` waits for every `connect` endpoint, s of real time.
pub const CONNECT_TIMEOUT_MS: u64 = 30_000;

/// Secure mode: this process's identity in a certificate directory made by
/// `echelon fleet certs`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Secure {
    /// Directory holding `ca.pem`, `<identity>.pem` and `<identity>-key.pem`.
    pub dir: PathBuf,
    /// `leader`, `collector` or `robot-<k>`.
    pub identity: String,
    /// Number of robots whose identities the access control knows.
    pub robots: u32,
    /// Per agent (from 1), the key expressions of its ROS 2 `cmd_vel` and
    /// `odom` ([`ros_acl`]), which only robot K and base K may publish.
    pub ros2: Vec<RosAcl>,
}

/// Agent K's ROS 2 keys in the access control: `cmd_vel` accepted only from
/// `robot-K`, `odom` only from `base-K` (its simulated base; a real robot
/// behind its own router, see docs/ros2.md).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RosAcl {
    /// Key expression of its `cmd_vel`, any type (`0/robot1/cmd_vel/*/*`).
    pub cmd_vel: String,
    /// Key expression of its `odom`, any type.
    pub odom: String,
    /// Key expression of its simulated base's ground truth, any type.
    pub truth: String,
    /// Key expression of its fixes, any type (published by its simulated
    /// base's motion capture), when it takes fixes from ROS 2.
    pub fixes: Option<String>,
}

impl RosAcl {
    /// What its simulated base publishes: odometry, ground truth, fixes.
    fn base_publishes(&self) -> impl Iterator<Item = String> + '_ {
        [self.odom.clone(), self.truth.clone()]
            .into_iter()
            .chain(self.fixes.clone())
    }

    /// What its robot reads: odometry and fixes.
    fn robot_reads(&self) -> impl Iterator<Item = String> + '_ {
        std::iter::once(self.odom.clone()).chain(self.fixes.clone())
    }

    /// Every key of the link.
    fn all(&self) -> impl Iterator<Item = String> + '_ {
        std::iter::once(self.cmd_vel.clone()).chain(self.base_publishes())
    }
}

/// The access-control keys of each agent's ROS 2 link.
pub fn ros_acl(links: &[echelon::scenario::Ros2Link]) -> Vec<RosAcl> {
    use echelon_ros2::keys::topic_key_any_type;
    links
        .iter()
        .map(|l| RosAcl {
            cmd_vel: topic_key_any_type(l.key_scheme, l.domain_id, &l.cmd_vel),
            odom: topic_key_any_type(l.key_scheme, l.domain_id, &l.odom),
            truth: topic_key_any_type(
                l.key_scheme,
                l.domain_id,
                &crate::ros2::ground_truth_topic(l),
            ),
            fixes: l
                .fixes
                .as_ref()
                .map(|f| topic_key_any_type(l.key_scheme, l.domain_id, &f.topic)),
        })
        .collect()
}

/// A session's Zenoh mode.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Mode {
    /// Links to the peers it connects to (and, by gossip, to the peers they
    /// know); routes nothing for others.
    #[default]
    Peer,
    /// Exactly one link, to a router, which routes everything for it; when the
    /// router goes away it keeps reconnecting.
    Client,
    /// Routes for its clients and peers and links to other routers
    /// (`fleet router`, the engine of `zenohd`).
    Router,
}

impl Mode {
    /// Zenoh's name of the mode.
    pub fn as_str(self) -> &'static str {
        match self {
            Mode::Peer => "peer",
            Mode::Client => "client",
            Mode::Router => "router",
        }
    }
}

impl std::fmt::Display for Mode {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

/// Where and how a process joins the fleet.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct NetOptions {
    /// Zenoh mode; `None`: peer, or the `zenoh_config` file's mode.
    pub mode: Option<Mode>,
    /// Endpoints to listen on, e.g. `tcp/127.0.0.1:7447` (`tls/…` in secure mode).
    pub listen: Vec<String>,
    /// Endpoints to connect to.
    pub connect: Vec<String>,
    /// A Zenoh configuration file (JSON5) to start from instead of the default.
    pub zenoh_config: Option<PathBuf>,
    /// Secure mode.
    pub secure: Option<Secure>,
}

/// The identities a fleet of `robots` robots uses (with a simulated ROS 2
/// base per robot, and its routers): each member's
/// ([`Member::identity`]), once.
pub fn identities(robots: u32) -> Vec<String> {
    let mut ids: Vec<String> = Vec::new();
    for m in Member::all(robots) {
        let id = m.identity();
        if !ids.contains(&id) {
            ids.push(id);
        }
    }
    ids
}

/// What `member` puts on the network in the fleet of `keys` (a fleet, or
/// [`Keys::any`]), given each agent's ROS 2 keys `ros`: the keys its
/// process publishes on, and for a router every key it forwards.
pub fn publishes(member: Member, keys: &Keys, ros: &[RosAcl]) -> Vec<String> {
    let ros_of = |k: u32| ros.get(k as usize - 1);
    match member {
        Member::Leader => vec![keys.reference(), keys.command()],
        Member::Operator => vec![keys.command()],
        Member::Robot(k) => [keys.state(k), keys.stats(k)]
            .into_iter()
            .chain(ros_of(k).map(|r| r.cmd_vel.clone()))
            .collect(),
        Member::Collector => Vec::new(),
        Member::Base(k) => ros_of(k)
            .into_iter()
            .flat_map(RosAcl::base_publishes)
            .collect(),
        Member::Excite(k) => ros_of(k).map(|r| r.cmd_vel.clone()).into_iter().collect(),
        Member::Router => std::iter::once(every_fleet())
            .chain(ros.iter().flat_map(RosAcl::all))
            .collect(),
    }
}

/// What `member` may subscribe to in the fleet of `keys`: the leader the
/// fleet command; a robot its leader stream (the reference or any robot's
/// state), with a safety filter every robot's state, the fleet command, and
/// its ROS 2 odometry; the collector and a router everything.
pub fn subscribes(member: Member, keys: &Keys, ros: &[RosAcl]) -> Vec<String> {
    let ros_of = |k: u32| ros.get(k as usize - 1);
    match member {
        Member::Leader => vec![keys.command()],
        Member::Operator => Vec::new(),
        Member::Robot(k) => [keys.reference(), keys.states(), keys.command()]
            .into_iter()
            .chain(ros_of(k).into_iter().flat_map(RosAcl::robot_reads))
            .collect(),
        Member::Base(k) => ros_of(k).map(|r| r.cmd_vel.clone()).into_iter().collect(),
        Member::Excite(k) => ros_of(k).map(|r| r.odom.clone()).into_iter().collect(),
        Member::Collector | Member::Router => std::iter::once(keys.everything())
            .chain(ros.iter().flat_map(RosAcl::all))
            .collect(),
    }
}

/// The session options of agent `agent`'s robot's own router: a client of
/// the first of `connect` that answers (one link; no gossip, so no
/// link to the robot's own nodes), in secure mode with the process's
/// identity (the robot's router must then be a `tls/` or `quic/` listener
/// trusting the fleet's CA: docs/real-robots.md).
pub fn robot_router(
    agent: u32,
    connect: &[String],
    fleet: &NetOptions,
) -> Result<NetOptions, FleetError> {
    if let Some(s) = &fleet.secure
        && let Some(e) = connect
            .iter()
            .find(|e| !(e.starts_with("tls/") || e.starts_with("quic/")))
    {
        return Err(FleetError::Config(format!(
            "agent {agent}: ros2.connect `{e}`: in secure mode a robot's router is reached over tls/ or quic/ with identity {} (docs/real-robots.md, \"Secure mode on real robots\")",
            s.identity
        )));
    }
    if fleet.secure.is_none()
        && let Some(e) = connect
            .iter()
            .find(|e| e.starts_with("tls/") || e.starts_with("quic/"))
    {
        return Err(FleetError::Config(format!(
            "agent {agent}: ros2.connect `{e}` needs certificates: give --secure DIR (or a tcp/ endpoint)"
        )));
    }
    Ok(NetOptions {
        mode: Some(Mode::Client),
        listen: Vec::new(),
        connect: connect.to_vec(),
        zenoh_config: None,
        secure: fleet.secure.clone(),
    })
}

/// The latch key `member` answers queries on with the fleet command in
/// force ([`crate::command`]): the leader's and each robot's. Every member
/// may ask them (`echelon/<fleet>/latch/**`).
pub fn answers(member: Member, keys: &Keys) -> Option<String> {
    match member {
        Member::Leader | Member::Robot(_) => Some(keys.latch(&member.liveliness())),
        _ => None,
    }
}

/// The Zenoh link protocol of the secure mode: QUIC (TLS 1.3 inside, mutual
/// authentication, certificate common names for the access control).
///
/// Not Zenoh's `tls` link: zenoh-link-tls 1.10 reads and writes one rustls
/// stream from two tasks without a lock (eclipse-zenoh/zenoh#2557, open), and
/// fleet processes died of it (SIGILL in rustls) about one run in six under
/// the secure tests. QUIC's streams (quinn) are split safely.
pub const SECURE_PROTOCOL: &str = "quic";

/// The link protocol of a fleet: [`SECURE_PROTOCOL`] with `--secure`, else TCP.
pub fn link_protocol(secure: bool) -> &'static str {
    if secure { SECURE_PROTOCOL } else { "tcp" }
}

/// The certificate common name of an identity: `echelon-<identity>`.
pub fn common_name(identity: &str) -> String {
    format!("echelon-{identity}")
}

/// The certificate and key files of `identity` in `dir`.
pub fn identity_files(dir: &Path, identity: &str) -> (PathBuf, PathBuf) {
    (
        dir.join(format!("{identity}.pem")),
        dir.join(format!("{identity}-key.pem")),
    )
}

/// The access-control section of the secure mode, generated from the
/// fleet's [`Member`]s: every member may subscribe, declare liveliness and
/// send; on arrival, a put is accepted only from an identity whose members
/// [publish](publishes) its key: references only from the leader's
/// certificate, robot `k`'s state and stats only from robot `k`'s; with
/// ROS 2 links, agent `k`'s `cmd_vel` only from robot `k` and its `odom` only
/// from base `k`, and rmw_zenoh's liveliness tokens (`@ros2_lv/**`) from
/// every member; the fleet command only from the `operator` and the
/// `leader`. Queries, queryables and replies (the command latches) are
/// allowed to every member: what a process learns from a latch answer can
/// only stop it ([`crate::command`]).
///
/// The subject of a message is the certificate of the link it arrives on, so
/// the origin is known only at its first hop: a router enforces these rules
/// on its clients' and peers' links, and accepts every fleet key from other
/// routers (`router-in`); a client, whose only link is its router, accepts
/// what the router forwards. Through routers the access control is therefore
/// enforced at the router the sender is linked to; in a peer mesh, at every
/// receiver.
pub fn access_control(robots: u32, ros2: &[RosAcl]) -> serde_json::Value {
    let ids = identities(robots);
    let everyone: Vec<String> = ids.iter().map(|i| common_name(i)).collect();
    let all = [every_fleet()];
    let mut rules = vec![
        json!({
            "id": "declare", "permission": "allow", "flows": ["egress", "ingress"],
            "messages": ["declare_subscriber", "liveliness_token", "liveliness_query",
                          "declare_liveliness_subscriber", "query", "declare_queryable",
                          "reply"],
            "key_exprs": all,
        }),
        json!({
            "id": "send", "permission": "allow", "flows": ["egress"],
            "messages": ["put"], "key_exprs": all,
        }),
    ];
    let mut subjects = vec![json!({"id": "members", "cert_common_names": everyone})];
    let mut policies = vec![json!({"rules": ["declare", "send"], "subjects": ["members"]})];
    if !ros2.is_empty() {
        let ros_keys: Vec<String> = ros2.iter().flat_map(RosAcl::all).collect();
        let mut declared = vec!["@ros2_lv/**"];
        declared.extend(ros_keys.iter().map(String::as_str));
        rules.push(json!({
            "id": "ros-declare", "permission": "allow", "flows": ["egress", "ingress"],
            "messages": ["declare_subscriber", "liveliness_token", "liveliness_query",
                          "declare_liveliness_subscriber", "query", "reply"],
            "key_exprs": declared,
        }));
        rules.push(json!({
            "id": "ros-send", "permission": "allow", "flows": ["egress"],
            "messages": ["put"], "key_exprs": ros_keys,
        }));
        policies.push(json!({"rules": ["ros-declare", "ros-send"], "subjects": ["members"]}));
    }
    // What arrives from an identity: what its members put (a router: what
    // it forwards).
    let any = Keys::any();
    let members = Member::all(robots);
    for id in &ids {
        let mut own: Vec<String> = Vec::new();
        for m in members.iter().filter(|m| m.identity() == *id) {
            for key in publishes(*m, &any, ros2) {
                if !own.contains(&key) {
                    own.push(key);
                }
            }
        }
        if own.is_empty() {
            continue;
        }
        let rule = format!("{id}-in");
        rules.push(json!({
            "id": rule, "permission": "allow", "flows": ["ingress"],
            "messages": ["put"], "key_exprs": own,
        }));
        subjects.push(json!({"id": id, "cert_common_names": [common_name(id)]}));
        policies.push(json!({"rules": [rule], "subjects": [id]}));
    }
    json!({
        "enabled": true,
        "default_permission": "deny",
        "rules": rules,
        "subjects": subjects,
        "policies": policies,
    })
}

fn set(config: &mut Config, key: &str, value: serde_json::Value) -> Result<(), FleetError> {
    config
        .insert_json5(key, &value.to_string())
        .map_err(|e| FleetError::Zenoh(format!("config {key}: {e}")))
}

/// The Zenoh configuration for these options.
pub fn config(opts: &NetOptions) -> Result<Config, FleetError> {
    let mut config = match &opts.zenoh_config {
        Some(path) => Config::from_file(path)
            .map_err(|e| FleetError::Zenoh(format!("{}: {e}", path.display())))?,
        None => {
            let mut c = Config::default();
            set(&mut c, "mode", json!(Mode::Peer.as_str()))?;
            set(&mut c, "scouting/multicast/enabled", json!(false))?;
            if opts.listen.is_empty() && opts.mode != Some(Mode::Client) {
                let proto = link_protocol(opts.secure.is_some());
                set(
                    &mut c,
                    "listen/endpoints",
                    json!([format!("{proto}/127.0.0.1:0")]),
                )?;
            }
            c
        }
    };
    if let Some(mode) = opts.mode {
        set(&mut config, "mode", json!(mode.as_str()))?;
    }
    if !opts.listen.is_empty() {
        set(&mut config, "listen/endpoints", json!(opts.listen))?;
    }
    if !opts.connect.is_empty() {
        set(&mut config, "connect/endpoints", json!(opts.connect))?;
        set(&mut config, "connect/timeout_ms", json!(CONNECT_TIMEOUT_MS))?;
        // A process needs its links to start; a router comes up alone and
        // links to the other sites' routers when they appear. Either way a
        // link lost later is retried for ever (a client re-opens its session
        // with its router, its subscriptions and tokens included).
        let router = opts.mode == Some(Mode::Router);
        set(&mut config, "connect/exit_on_failure", json!(!router))?;
        set(
            &mut config,
            "connect/retry",
            json!({"period_init_ms": 50, "period_max_ms": 500, "period_increase_factor": 2}),
        )?;
    }
    if let Some(s) = &opts.secure {
        set(&mut config, "transport/link/tls", tls(s)?)?;
        set(
            &mut config,
            "access_control",
            access_control(s.robots, &s.ros2),
        )?;
    }
    Ok(config)
}

/// The TLS section of the secure mode (Zenoh reads it for QUIC links too):
/// `s.identity`'s certificate on both sides of every link, the fleet CA as
/// the only root, mutual authentication.
fn tls(s: &Secure) -> Result<serde_json::Value, FleetError> {
    let ca = s.dir.join("ca.pem");
    let (cert, key) = identity_files(&s.dir, &s.identity);
    for f in [&ca, &cert, &key] {
        if !f.is_file() {
            return Err(FleetError::Config(format!(
                "secure mode needs {} (make the certificates with `echelon fleet certs {}`)",
                f.display(),
                s.dir.display()
            )));
        }
    }
    let path = |p: &PathBuf| json!(p.display().to_string());
    Ok(json!({
        "root_ca_certificate": path(&ca),
        "listen_certificate": path(&cert),
        "listen_private_key": path(&key),
        "connect_certificate": path(&cert),
        "connect_private_key": path(&key),
        "enable_mtls": true,
    }))
}

/// Opens a session (blocks until every `connect` endpoint is reached, or fails).
pub fn open(opts: &NetOptions) -> Result<Session, FleetError> {
    let config = config(opts)?;
    zenoh::open(config)
        .wait()
        .map_err(|e| FleetError::Zenoh(format!("opening the session: {e}")))
}

/// Publishes one encoded message, stamped with the session's timestamp
/// (the receivers' latency measure, [`crate::latency`]).
pub(crate) fn publish(
    session: &Session,
    publisher: &zenoh::pubsub::Publisher<'_>,
    bytes: &[u8],
) -> Result<(), FleetError> {
    publisher
        .put(bytes.to_vec())
        .timestamp(session.new_timestamp())
        .wait()
        .map_err(|e| FleetError::Zenoh(format!("publishing: {e}")))
}

/// Puts `payload` on `key` (a non-declared publication, e.g. a robot's
/// stats), stamped like [`publish`]; errors are ignored (best effort).
pub(crate) fn put_stamped(session: &Session, key: &str, payload: impl Into<ZBytes>) {
    let _ = session
        .put(key, payload)
        .timestamp(session.new_timestamp())
        .wait();
}

/// A random source id: the low bits of a hash of the process id and the time.
pub(crate) fn rand_source() -> u32 {
    use std::hash::{BuildHasher, Hasher};
    let mut h = std::collections::hash_map::RandomState::new().build_hasher();
    h.write_u32(std::process::id());
    h.write_u64(crate::unix_nanos());
    h.finish() as u32
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn default_config_is_peer_without_multicast() {
        let c = config(&NetOptions {
            listen: vec!["tcp/127.0.0.1:7999".into()],
            connect: vec!["tcp/127.0.0.1:7998".into()],
            ..NetOptions::default()
        })
        .unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(c.get_json("mode").ok().as_deref(), Some("\"peer\""));
        assert_eq!(
            c.get_json("scouting/multicast/enabled").ok().as_deref(),
            Some("false")
        );
        assert!(
            c.get_json("listen/endpoints")
                .unwrap_or_default()
                .contains("7999")
        );
    }

    #[test]
    fn a_client_does_not_listen_and_a_router_outlives_its_connects() {
        let client = config(&NetOptions {
            mode: Some(Mode::Client),
            connect: vec!["tcp/127.0.0.1:7998".into()],
            ..NetOptions::default()
        })
        .unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(client.get_json("mode").ok().as_deref(), Some("\"client\""));
        assert!(
            !client
                .get_json("listen/endpoints")
                .unwrap_or_default()
                .contains("127.0.0.1:0")
        );
        assert_eq!(
            client.get_json("connect/exit_on_failure").ok().as_deref(),
            Some("true")
        );
        let router = config(&NetOptions {
            mode: Some(Mode::Router),
            listen: vec!["tcp/127.0.0.1:7999".into()],
            connect: vec!["tcp/127.0.0.1:7998".into()],
            ..NetOptions::default()
        })
        .unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(router.get_json("mode").ok().as_deref(), Some("\"router\""));
        assert_eq!(
            router.get_json("connect/exit_on_failure").ok().as_deref(),
            Some("false")
        );
    }

    /// What the scenario accepts as a robot's router Zenoh parses as an
    /// endpoint, and a robot's own session is a client of it, with
    /// certificates exactly when the link needs them.
    #[test]
    fn a_robots_router_is_a_zenoh_endpoint_reached_as_a_client() {
        let plain = [
            "tcp/192.168.1.21:7447",
            "udp/robot-1.lab:7447",
            "tcp/[fe80::1]:7447#iface=eth0",
        ];
        let secured = ["tls/10.0.0.2:7448", "quic/robot-2:7448"];
        for e in plain.iter().chain(&secured) {
            echelon::scenario::check_endpoint(e).unwrap_or_else(|m| panic!("{m}"));
            e.parse::<zenoh::config::EndPoint>()
                .unwrap_or_else(|m| panic!("{e}: {m}"));
        }
        let fleet = NetOptions {
            mode: Some(Mode::Client),
            connect: vec!["tcp/127.0.0.1:7447".into()],
            ..NetOptions::default()
        };
        let robot = robot_router(1, &[plain[0].into(), plain[1].into()], &fleet)
            .unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(robot.mode, Some(Mode::Client));
        assert_eq!(
            robot.connect,
            vec![plain[0].to_owned(), plain[1].to_owned()]
        );
        assert!(robot.listen.is_empty() && robot.secure.is_none());
        let c = config(&robot).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(c.get_json("mode").ok().as_deref(), Some("\"client\""));
        let e = robot_router(2, &[secured[0].into()], &fleet)
            .err()
            .unwrap_or_else(|| panic!("tls without certificates"));
        assert!(
            e.to_string().contains("agent 2") && e.to_string().contains("--secure"),
            "{e}"
        );
        let secure = NetOptions {
            secure: Some(Secure {
                dir: "certs".into(),
                identity: "robot-3".into(),
                robots: 3,
                ros2: Vec::new(),
            }),
            ..fleet
        };
        let robot =
            robot_router(3, &secured.map(String::from), &secure).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(robot.secure, secure.secure);
        let e = robot_router(3, &[plain[0].into()], &secure)
            .err()
            .unwrap_or_else(|| panic!("tcp in secure mode"));
        assert!(e.to_string().contains("tls/ or quic/"), "{e}");
    }

    #[test]
    fn access_control_is_accepted_by_zenoh() {
        let mut c = Config::default();
        let ros = vec![RosAcl {
            cmd_vel: "0/robot1/cmd_vel/*/*".into(),
            odom: "0/robot1/odom/*/*".into(),
            truth: "0/robot1/ground_truth/*/*".into(),
            fixes: Some("0/mocap/robot1/pose/*/*".into()),
        }];
        set(&mut c, "access_control", access_control(3, &ros)).unwrap_or_else(|e| panic!("{e}"));
        let acl = c.get_json("access_control").unwrap_or_default();
        assert!(acl.contains("echelon-robot-3") && acl.contains("echelon/*/reference"));
        assert!(acl.contains("echelon-router") && acl.contains("router-in"));
    }

    use serde_json::Value;
    use zenoh::key_expr::keyexpr;

    fn includes(expr: &str, key: &str) -> bool {
        match (keyexpr::new(expr), keyexpr::new(key)) {
            (Ok(e), Ok(k)) => e.includes(k),
            _ => panic!("not key expressions: {expr}, {key}"),
        }
    }

    fn strs(v: &Value) -> Vec<&str> {
        v.as_array()
            .map(|a| a.iter().filter_map(Value::as_str).collect())
            .unwrap_or_default()
    }

    /// Whether `acl` lets a message `message` on `key` flow `flow` from (or
    /// to) the certificate `cn`: zenoh's reading (default deny; allowed
    /// when a policy of a subject naming `cn` has a rule of that flow and
    /// message whose key expressions include `key`).
    fn allows(acl: &Value, cn: &str, flow: &str, message: &str, key: &str) -> bool {
        assert_eq!(acl["default_permission"], "deny");
        let subjects: Vec<&str> = acl["subjects"]
            .as_array()
            .into_iter()
            .flatten()
            .filter(|s| strs(&s["cert_common_names"]).contains(&cn))
            .filter_map(|s| s["id"].as_str())
            .collect();
        let rules: Vec<&str> = acl["policies"]
            .as_array()
            .into_iter()
            .flatten()
            .filter(|p| strs(&p["subjects"]).iter().any(|s| subjects.contains(s)))
            .flat_map(|p| strs(&p["rules"]))
            .collect();
        acl["rules"].as_array().into_iter().flatten().any(|r| {
            r["permission"] == "allow"
                && rules.contains(&r["id"].as_str().unwrap_or_default())
                && strs(&r["flows"]).contains(&flow)
                && strs(&r["messages"]).contains(&message)
                && strs(&r["key_exprs"]).iter().any(|e| includes(e, key))
        })
    }

    /// Agents `1..=n`'s ROS 2 keys as [`ros_acl`] writes them.
    fn ros_links(n: u32) -> Vec<RosAcl> {
        (1..=n)
            .map(|k| RosAcl {
                cmd_vel: format!("0/robot{k}/cmd_vel/*/*"),
                odom: format!("0/robot{k}/odom/*/*"),
                truth: format!("0/robot{k}/ground_truth/*/*"),
                fixes: (k % 2 == 1).then(|| format!("0/robot{k}/pose/*/*")),
            })
            .collect()
    }

    /// A concrete key of a ROS 2 key expression (any type).
    fn concrete(expr: &str) -> String {
        expr.replace('*', "T")
    }

    /// For every fleet size, with and without ROS 2 links, and every
    /// identity: a put arriving from it is allowed exactly on the keys its
    /// members publish, in any fleet; every member may declare what it
    /// subscribes to.
    #[test]
    fn each_identity_may_put_exactly_what_its_members_publish() {
        for robots in 1..=4 {
            for with_ros in [0, 1, robots] {
                let ros = ros_links(with_ros);
                let acl = access_control(robots, &ros);
                let members = Member::all(robots);
                let fleets = [Keys::new("lab"), Keys::new("lab-2")];
                // Every key any member puts, in two fleets, and keys no
                // member of this fleet size puts.
                let mut universe: Vec<String> = Vec::new();
                for keys in &fleets {
                    for m in members.iter().filter(|m| **m != Member::Router) {
                        universe.extend(publishes(*m, keys, &ros).iter().map(|k| concrete(k)));
                    }
                    universe.push(keys.state(robots + 1));
                    universe.push(keys.stats(robots + 1));
                    universe.push(keys.alive("x"));
                }
                universe.extend(
                    ros_links(robots + 1)
                        .iter()
                        .flat_map(|r| r.all().map(|k| concrete(&k)).collect::<Vec<_>>()),
                );
                for id in identities(robots) {
                    let cn = common_name(&id);
                    let own: Vec<Member> = members
                        .iter()
                        .copied()
                        .filter(|m| m.identity() == id)
                        .collect();
                    assert!(!own.is_empty(), "{id}");
                    for key in &universe {
                        let expected = own.iter().any(|m| {
                            fleets.iter().any(|keys| {
                                publishes(*m, keys, &ros).iter().any(|p| includes(p, key))
                            })
                        });
                        assert_eq!(
                            allows(&acl, &cn, "ingress", "put", key),
                            expected,
                            "{robots} robots, {with_ros} ROS 2 links: {id} putting {key}"
                        );
                    }
                    for m in &own {
                        for msg in ["query", "reply"] {
                            assert!(allows(&acl, &cn, "egress", msg, &fleets[0].latches()));
                        }
                        if let Some(key) = answers(*m, &fleets[0]) {
                            for msg in ["declare_queryable", "reply"] {
                                assert!(
                                    allows(&acl, &cn, "egress", msg, &key)
                                        && allows(&acl, &cn, "ingress", msg, &key),
                                    "{m} answering on {key}"
                                );
                            }
                        }
                        for key in subscribes(*m, &fleets[0], &ros) {
                            assert!(
                                allows(&acl, &cn, "egress", "declare_subscriber", &key)
                                    && allows(&acl, &cn, "ingress", "declare_subscriber", &key),
                                "{m} subscribing to {key}"
                            );
                        }
                    }
                }
                // Nobody outside the fleet's identities may put anything.
                for key in &universe {
                    assert!(!allows(&acl, "echelon-robot-99", "ingress", "put", key));
                }
                // The fleet command: from the operator and the leader only
                // (and a router, which forwards everything of the fleet).
                for keys in &fleets {
                    for id in identities(robots) {
                        assert_eq!(
                            allows(&acl, &common_name(&id), "ingress", "put", &keys.command()),
                            ["operator", "leader", "router"].contains(&id.as_str()),
                            "{id} putting the command"
                        );
                    }
                }
            }
        }
    }

    /// The tasks' declarations are the ones the access control is made of:
    /// what a leader and robot publish is what [`publishes`] says, what they
    /// subscribe to is within [`subscribes`], their tokens are their names.
    #[test]
    fn the_roles_declare_what_the_access_control_allows() {
        use crate::faults::FaultSpec;
        use crate::leader::{Leader, LeaderTask};
        use crate::robot::{Robot, RobotTask};
        use crate::runtime::Task;

        let (s, _, reference) = crate::testing::fast_circle();
        let keys = Keys::new("lab");
        let within = |declared: &[String], allowed: &[String], what: &str| {
            for d in declared {
                assert!(allowed.iter().any(|a| includes(a, d)), "{what}: {d}");
            }
        };
        let leader = LeaderTask::new(Leader::new(reference, 50.0, 1.0, 1), keys.clone());
        let m = Member::Leader;
        assert_eq!(leader.outputs(), publishes(m, &keys, &[]));
        within(&leader.inputs(), &subscribes(m, &keys, &[]), "leader");
        assert_eq!(leader.tokens(), vec![keys.alive(&m.liveliness())]);
        for k in 1..=2 {
            let config = crate::testing::robot_config(&s, k, FaultSpec::default());
            let robot = RobotTask::new(Robot::simulated(config, 1), keys.clone());
            let m = Member::Robot(k);
            let mut out = robot.outputs();
            out.push(keys.stats(k));
            assert_eq!(out, publishes(m, &keys, &[]));
            within(&robot.inputs(), &subscribes(m, &keys, &[]), "robot");
            assert_eq!(robot.tokens(), vec![keys.alive(&m.liveliness())]);
        }
    }
}
