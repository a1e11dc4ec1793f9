//! The secure mode's identities and access control, generated from the
//! fleet's [`Member`]s: who may publish and subscribe to which key, each
//! agent's ROS 2 keys, and the access-control section of a Zenoh
//! configuration.

use std::path::{Path, PathBuf};

use serde_json::json;

use crate::keys::{Keys, every_fleet};
use crate::role::Member;

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
    /// Key expressions of its base's safety words (hazards, e-stop), any
    /// type, when it listens to them.
    pub safety: Vec<String>,
}

impl RosAcl {
    /// What its simulated base publishes: odometry, ground truth, fixes,
    /// safety words.
    fn base_publishes(&self) -> impl Iterator<Item = String> + '_ {
        [self.odom.clone(), self.truth.clone()]
            .into_iter()
            .chain(self.fixes.clone())
            .chain(self.safety.iter().cloned())
    }

    /// What its robot reads: odometry, fixes and its base's safety words.
    fn robot_reads(&self) -> impl Iterator<Item = String> + '_ {
        std::iter::once(self.odom.clone())
            .chain(self.fixes.clone())
            .chain(self.safety.iter().cloned())
    }

    /// Every key of the link.
    pub(super) fn all(&self) -> impl Iterator<Item = String> + '_ {
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
            safety: l
                .hazards
                .iter()
                .chain(&l.estop)
                .map(|t| topic_key_any_type(l.key_scheme, l.domain_id, t))
                .collect(),
        })
        .collect()
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
        Member::Operator => vec![keys.command(), keys.heartbeat()],
        // A robot puts its own fleet stop when its base reports a hazard.
        Member::Robot(k) => [keys.state(k), keys.stats(k), keys.halt(k)]
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
        Member::Leader => vec![keys.command(), keys.halts()],
        // The operator's heartbeat reads the reference for the fleet's time.
        Member::Operator => vec![keys.reference()],
        Member::Robot(k) => [
            keys.reference(),
            keys.states(),
            keys.halts(),
            keys.command(),
            keys.heartbeat(),
        ]
        .into_iter()
        .chain(ros_of(k).into_iter().flat_map(RosAcl::robot_reads))
        .collect(),
        // A simulated base reads the reference for the fleet's time
        // (`--fault-at`).
        Member::Base(k) => ros_of(k)
            .map(|r| r.cmd_vel.clone())
            .into_iter()
            .chain(std::iter::once(keys.reference()))
            .collect(),
        Member::Excite(k) => ros_of(k).map(|r| r.odom.clone()).into_iter().collect(),
        Member::Collector | Member::Router => std::iter::once(keys.everything())
            .chain(ros.iter().flat_map(RosAcl::all))
            .collect(),
    }
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

/// The key `member` answers `fleet doctor`'s probe on ([`crate::probe`]):
/// `echelon/<fleet>/probe/<its liveliness name>`, a router's for every
/// fleet. Every member may declare it, ask it (`fleet doctor` as the
/// `operator`) and reply: an answer says who a process is and what its
/// clock reads, and moves nothing.
pub fn probe_key(member: Member, keys: &Keys) -> String {
    match member {
        Member::Router => Keys::any().probe(&member.liveliness()),
        _ => keys.probe(&member.liveliness()),
    }
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
/// `leader`; robot `k`'s halt key (its own stop-only fleet stop) only from
/// robot `k`. Queries, queryables and replies (the command latches, the
/// probes of [`probe_key`]) are allowed to every member: what a process
/// learns from a latch answer can only stop it ([`crate::command`]), from
/// a probe only who answers and its clock.
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
