use super::*;
use crate::keys::Keys;
use crate::role::Member;

/// The Zenoh configuration [`config`] builds from `opts`, read key by key:
/// the JSON text at a key, empty where there is none.
fn zenoh_config(opts: &NetOptions) -> impl Fn(&str) -> String + use<> {
    let c = config(opts).unwrap_or_else(|e| panic!("{e}"));
    move |key| c.get_json(key).unwrap_or_default()
}

#[test]
fn default_config_is_peer_without_multicast() {
    let c = zenoh_config(&NetOptions {
        listen: vec!["tcp/127.0.0.1:7999".into()],
        connect: vec!["tcp/127.0.0.1:7998".into()],
        ..NetOptions::default()
    });
    assert_eq!(c("mode"), "\"peer\"");
    assert_eq!(c("scouting/multicast/enabled"), "false");
    assert!(c("listen/endpoints").contains("7999"));
}

#[test]
fn a_client_does_not_listen_and_a_router_outlives_its_connects() {
    let client = zenoh_config(&NetOptions {
        mode: Some(Mode::Client),
        connect: vec!["tcp/127.0.0.1:7998".into()],
        ..NetOptions::default()
    });
    assert_eq!(client("mode"), "\"client\"");
    assert!(!client("listen/endpoints").contains("127.0.0.1:0"));
    assert_eq!(client("connect/exit_on_failure"), "true");
    let router = zenoh_config(&NetOptions {
        mode: Some(Mode::Router),
        listen: vec!["tcp/127.0.0.1:7999".into()],
        connect: vec!["tcp/127.0.0.1:7998".into()],
        ..NetOptions::default()
    });
    assert_eq!(router("mode"), "\"router\"");
    assert_eq!(router("connect/exit_on_failure"), "false");
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
    assert_eq!(zenoh_config(&robot)("mode"), "\"client\"");
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
    // An on-board robot next to its robot's router: loopback only, plain.
    for local in [
        vec!["tcp/127.0.0.1:7447".to_owned()],
        vec!["tcp/localhost:7447".to_owned(), "tcp/[::1]:7447".to_owned()],
    ] {
        let robot = robot_router(3, &local, &secure).unwrap_or_else(|e| panic!("{e}"));
        assert!(robot.secure.is_none(), "{local:?}");
    }
    // One endpoint off the machine: the secure rule again.
    let mixed = [
        "tcp/127.0.0.1:7447".to_owned(),
        "tcp/10.0.0.2:7447".to_owned(),
    ];
    assert!(robot_router(3, &mixed, &secure).is_err());
    for (e, local) in [
        ("tcp/127.0.0.1:7447", true),
        ("tcp/127.3.2.1:1", true),
        ("udp/localhost:7447#iface=lo", true),
        ("tls/127.0.0.1:7447", false),
        ("tcp/128.0.0.1:7447", false),
        ("tcp/[fe80::1]:7447", false),
    ] {
        assert_eq!(super::is_loopback_endpoint(e), local, "{e}");
    }
}

#[test]
fn access_control_is_accepted_by_zenoh() {
    let mut c = Config::default();
    let ros = vec![RosAcl {
        cmd_vel: "0/robot1/cmd_vel/*/*".into(),
        odom: "0/robot1/odom/*/*".into(),
        truth: "0/robot1/ground_truth/*/*".into(),
        fixes: Some("0/mocap/robot1/pose/*/*".into()),
        safety: vec!["0/robot1/hazard_detection/*/*".into()],
    }];
    set(&mut c, "access_control", access_control(3, &ros)).unwrap_or_else(|e| panic!("{e}"));
    let acl = c.get_json("access_control").unwrap_or_default();
    assert!(acl.contains("echelon-robot-3") && acl.contains("echelon/*/reference"));
    assert!(acl.contains("echelon-router") && acl.contains("router-in"));
}

use serde_json::Value;

#[path = "../../tests/common/acl.rs"]
mod acl_reading;
use acl_reading::{includes, strs};

/// Whether `acl` lets a message `message` on `key` flow `flow` from (or
/// to) the certificate `cn` ([`acl_reading::allows`]).
fn allows(acl: &Value, cn: &str, flow: &str, message: &str, key: &str) -> bool {
    let named = |s: &Value| strs(&s["cert_common_names"]).contains(&cn);
    acl_reading::allows(acl, named, flow, message, key)
}

/// Agents `1..=n`'s ROS 2 keys as [`ros_acl`] writes them.
fn ros_links(n: u32) -> Vec<RosAcl> {
    (1..=n)
        .map(|k| RosAcl {
            cmd_vel: format!("0/robot{k}/cmd_vel/*/*"),
            odom: format!("0/robot{k}/odom/*/*"),
            truth: format!("0/robot{k}/ground_truth/*/*"),
            fixes: (k % 2 == 1).then(|| format!("0/robot{k}/pose/*/*")),
            safety: match k % 3 {
                0 => Vec::new(),
                1 => vec![format!("0/robot{k}/hazard_detection/*/*")],
                _ => vec![
                    format!("0/robot{k}/hazard_detection/*/*"),
                    format!("0/robot{k}/platform/emergency_stop/*/*"),
                ],
            },
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
                        fleets
                            .iter()
                            .any(|keys| publishes(*m, keys, &ros).iter().any(|p| includes(p, key)))
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
                    // `fleet doctor`'s probes: answered by every member, asked by all.
                    let probe = concrete(&probe_key(*m, &fleets[0]));
                    for msg in ["declare_queryable", "reply"] {
                        assert!(
                            allows(&acl, &cn, "egress", msg, &probe)
                                && allows(&acl, &cn, "ingress", msg, &probe),
                            "{m} answering its probe on {probe}"
                        );
                    }
                    assert!(allows(&acl, &cn, "egress", "query", &probe));
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
            // (and a router, which forwards everything of the fleet);
            // robot 1's halt key from robot 1 only.
            for keys in &fleets {
                for id in identities(robots) {
                    assert_eq!(
                        allows(&acl, &common_name(&id), "ingress", "put", &keys.halt(1)),
                        ["robot-1", "router"].contains(&id.as_str()),
                        "{id} putting robot 1's halt"
                    );
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
        // Its state and counters, and the fleet stop it puts when its base
        // reports a hazard.
        let mut out = robot.outputs();
        out.push(keys.halt(k));
        assert_eq!(out, publishes(m, &keys, &[]));
        within(&robot.inputs(), &subscribes(m, &keys, &[]), "robot");
        assert_eq!(robot.tokens(), vec![keys.alive(&m.liveliness())]);
    }
}

/// The secure mode's links (QUIC, through a router, access control on): a
/// leader that publishes a burst of reference samples and closes its
/// session at once, after [`flush`], loses none of them: a collector behind
/// the same router receives every one, in order. (Without the flush, QUIC's
/// close abandons what the router has not received yet.) Rounds of
/// randomized burst sizes.
#[test]
fn last_words_flushed_before_close_all_arrive_over_quic() {
    use crate::keys::Keys;
    use crate::role::Member;
    use std::time::{Duration, Instant};

    let dir = tempfile::tempdir().unwrap_or_else(|e| panic!("{e}"));
    let certs = dir.path().join("certs");
    crate::certs::generate(&crate::certs::CertOptions {
        dir: certs.clone(),
        robots: 1,
        hosts: Vec::new(),
    })
    .unwrap_or_else(|e| panic!("{e}"));
    let secure = |member: Member| {
        Some(Secure {
            dir: certs.clone(),
            identity: member.identity(),
            robots: 1,
            ros2: Vec::new(),
        })
    };
    let port = crate::up::free_ports(1).unwrap_or_else(|e| panic!("{e}"))[0];
    let endpoint = format!("{SECURE_PROTOCOL}/127.0.0.1:{port}");
    let _router = open(&NetOptions {
        mode: Some(Mode::Router),
        listen: vec![endpoint.clone()],
        secure: secure(Member::Router),
        ..NetOptions::default()
    })
    .unwrap_or_else(|e| panic!("{e}"));
    let client = |member: Member| {
        open(&NetOptions {
            mode: Some(Mode::Client),
            connect: vec![endpoint.clone()],
            secure: secure(member),
            ..NetOptions::default()
        })
        .unwrap_or_else(|e| panic!("{e}"))
    };
    let keys = Keys::new("flush");
    let collector = client(Member::Collector);
    // Unbounded: the subscriber never pushes back on the router.
    let (tx, heard) = std::sync::mpsc::channel();
    let _sub = collector
        .declare_subscriber(keys.reference())
        .callback(move |s| {
            let bytes = s.payload().to_bytes();
            let _ = tx.send(u32::from_le_bytes(
                bytes.as_ref().try_into().unwrap_or_default(),
            ));
        })
        .wait()
        .unwrap_or_else(|e| panic!("{e}"));
    // A seed of its own each run: burst sizes from 1 to 5 000.
    let mut seed = u64::from(rand_source()) | 1;
    for round in 0..4 {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        let n = 1 + (seed % 5_000) as u32;
        let leader = client(Member::Leader);
        // Blocking, so that no queue drops a sample: what is tested is the
        // close, not congestion.
        let publisher = leader
            .declare_publisher(keys.reference())
            .congestion_control(zenoh::qos::CongestionControl::Block)
            .wait()
            .unwrap_or_else(|e| panic!("{e}"));
        // The subscription is known to the router before the burst.
        std::thread::sleep(Duration::from_millis(200));
        for i in 0..n {
            send(&leader, &publisher, &i.to_le_bytes(), None).unwrap_or_else(|e| panic!("{e}"));
        }
        flush(
            &leader,
            &keys.alive(&Member::Leader.liveliness()),
            FLUSH_TIMEOUT,
        )
        .unwrap_or_else(|e| panic!("round {round}: {e}"));
        drop(publisher);
        leader.close().wait().unwrap_or_else(|e| panic!("{e}"));
        let deadline = Instant::now() + Duration::from_secs(20);
        let mut got = 0u32;
        while got < n {
            let left = deadline.saturating_duration_since(Instant::now());
            match heard.recv_timeout(left) {
                Ok(i) => {
                    assert_eq!(i, got, "round {round}: out of order");
                    got += 1;
                }
                Err(_) => break,
            }
        }
        assert_eq!(got, n, "round {round}: {got} of {n} arrived");
    }
    let _ = collector.close().wait();
}
