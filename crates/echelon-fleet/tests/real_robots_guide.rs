//! The sample `rmw_zenohd` configuration of docs/real-robots.md ("Secure
//! mode on real robots") is a Zenoh configuration this Zenoh accepts, and
//! its access control is the fleet's rule for the agent it is written for:
//! on the network, only `echelon-robot-1`'s certificate may put agent 1's
//! `cmd_vel`, as echelon's own access control says (`net::ros_acl`, from the
//! scenario `examples/real-robots/jackal-jazzy.toml`), and the robot's own
//! nodes (loopback) keep full access. If the scenario, the key scheme or the
//! fleet's identities change, this fails until the guide follows.
#![allow(clippy::unwrap_used)] // tests fail loudly by design

use std::path::Path;

use echelon::scenario::Scenario;
use echelon_fleet::net::{common_name, ros_acl};
use serde_json::Value;

#[path = "common/acl.rs"]
mod acl;
use acl::{allows, strs};

fn root() -> &'static Path {
    Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../.."))
}

/// The first ```json5 block of the guide.
fn sample() -> String {
    let path = root().join("docs/real-robots.md");
    let doc = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let start = doc.find("```json5\n").expect("a ```json5 block") + "```json5\n".len();
    let len = doc[start..].find("\n```").expect("its end");
    doc[start..start + len].to_owned()
}

/// A link showing the certificate `cn` from the network (not loopback).
/// (Zenoh writes an absent subject attribute as `null`.)
fn cert(cn: &str) -> impl Fn(&Value) -> bool + '_ {
    move |s: &Value| strs(&s["cert_common_names"]).contains(&cn) && s["interfaces"].is_null()
}

/// A link on loopback without a certificate (the robot's own nodes).
fn on_robot(s: &Value) -> bool {
    strs(&s["interfaces"]).contains(&"lo") && s["cert_common_names"].is_null()
}

#[test]
fn the_guides_rmw_zenohd_sample_is_the_fleets_rule_for_agent_1() {
    let config = zenoh::Config::from_json5(&sample()).unwrap_or_else(|e| panic!("{e}"));
    let acl: Value = serde_json::from_str(&config.get_json("access_control").unwrap()).unwrap();
    assert_eq!(acl["enabled"], true);

    let s = Scenario::load(&root().join("examples/real-robots/jackal-jazzy.toml")).unwrap();
    let links = s.fleet().unwrap().ros2;
    let ros = ros_acl(&links);
    let concrete = |expr: &str| expr.replace('*', "T");
    let cmd_vel = concrete(&ros[0].cmd_vel);
    let odom = concrete(&ros[0].odom);
    assert_eq!(ros[0].cmd_vel, "0/j100_0001/cmd_vel/*/*");

    let robot1 = common_name("robot-1");
    // Robot process 1 may command agent 1, subscribe to its odometry and
    // receive it, and declare rmw_zenoh's liveliness tokens; and nothing
    // else: not put agent 1's odometry, nor other topics.
    let token = "@ros2_lv/0/abc/0/1/MP/%/%j100_0001/echelon_robot/%j100_0001%cmd_vel";
    for (allowed, flow, message, key) in [
        (true, "ingress", "put", cmd_vel.as_str()),
        (true, "ingress", "declare_subscriber", odom.as_str()),
        (true, "egress", "put", odom.as_str()),
        (true, "ingress", "liveliness_token", token),
        (false, "ingress", "put", odom.as_str()),
        (
            false,
            "ingress",
            "put",
            "0/j100_0001/platform/emergency_stop/T/T",
        ),
    ] {
        assert_eq!(
            allows(&acl, cert(&robot1), flow, message, key),
            allowed,
            "robot-1 {flow} {message} {key}"
        );
    }
    // Other fleet identities, and links without a certificate from the
    // network, may not command it.
    for id in [
        "robot-2",
        "robot-3",
        "leader",
        "collector",
        "base-1",
        "router",
    ] {
        let cn = common_name(id);
        assert!(!allows(&acl, cert(&cn), "ingress", "put", &cmd_vel), "{id}");
    }
    assert!(!allows(
        &acl,
        |s| s["interfaces"].is_null() && s["cert_common_names"].is_null(),
        "ingress",
        "put",
        &cmd_vel
    ));
    // The robot's own nodes, on loopback, keep everything.
    for key in [cmd_vel.as_str(), odom.as_str(), "0/j100_0001/tf/T/T"] {
        for flow in ["ingress", "egress"] {
            assert!(allows(&acl, on_robot, flow, "put", key), "{flow} {key}");
        }
    }
    assert!(allows(
        &acl,
        on_robot,
        "ingress",
        "liveliness_token",
        "@ros2_lv/0/x/0/0/NN/%/%/node"
    ));

    // Its TLS listener shows base 1's certificate, which the fleet's own
    // access control accepts agent 1's odometry from.
    let tls: Value = serde_json::from_str(&config.get_json("transport/link/tls").unwrap()).unwrap();
    assert_eq!(tls["enable_mtls"], true);
    assert!(
        tls["listen_certificate"]
            .as_str()
            .unwrap()
            .ends_with("/base-1.pem")
    );
    let fleet_acl = echelon_fleet::net::access_control(3, &ros);
    assert!(allows(
        &fleet_acl,
        |s| strs(&s["cert_common_names"]) == [common_name("base-1")],
        "ingress",
        "put",
        &odom
    ));
}
