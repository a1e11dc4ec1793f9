//! Routers: one killed and started again mid-run, two sites linked.

use super::*;

/// A free loopback TCP endpoint.
fn free_endpoint() -> String {
    let l = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    format!("tcp/127.0.0.1:{}", l.local_addr().unwrap().port())
}

/// Router topology, started by hand as on a site: killing the router
/// (SIGKILL) mid-run cuts every link, so each robot loses its leader and
/// applies its link-loss policy (`stop`); a router started again on the same
/// endpoint is found by every client, which re-declares itself, and the
/// robots resume and converge; the collector records again.
#[test]
fn robots_lose_the_link_when_the_router_dies_and_resume_when_it_returns() {
    let _fleet = common::one_fleet_at_a_time();
    let dir = tempfile::tempdir().unwrap();
    let ep = free_endpoint();
    let scenario = fixture("fast-circle-stop.toml");
    let out = dir.path().display().to_string();
    let router = || spawn(&["fleet", "router", "--listen", &ep]);
    let client = ["--mode", "client", "--connect", &ep];
    let run = ["--time-scale", "5", "--duration", "60"];
    let mut first_router = router();
    let collector = spawn(
        &[
            &["fleet", "collector", &scenario, "--out", &out][..],
            &client,
        ]
        .concat(),
    );
    let robots: Vec<Guard> = ["1", "2"]
        .iter()
        .map(|k| {
            spawn(
                &[
                    &["fleet", "robot", &scenario, "--agent", k][..],
                    &run,
                    &client,
                ]
                .concat(),
            )
        })
        .collect();
    let wait = [
        "--wait-for",
        "collector",
        "--wait-for",
        "robot/1",
        "--wait-for",
        "robot/2",
    ];
    let leader = spawn(&[&["fleet", "leader", &scenario][..], &run, &wait, &client].concat());
    // The leader starts its clock about a second after it is spawned; at ×5
    // the router dies near t = 10 s of fleet time and is back after about
    // 0.6 s of real time (3 s of fleet time, plus the clients' reconnection).
    std::thread::sleep(Duration::from_millis(3000));
    first_router.0.kill().unwrap();
    first_router.0.wait().unwrap();
    std::thread::sleep(Duration::from_millis(600));
    let second_router = router();
    let leader = leader.report();
    let robots: Vec<Value> = robots.into_iter().map(Guard::report).collect();
    std::thread::sleep(Duration::from_millis(300));
    collector.terminate();
    let collector = collector.report();
    second_router.terminate();
    let router_report = second_router.report();
    // Robot 1 follows the reference, robot 2 robot 1's state.
    let streams = [u(&leader, &["published"]), u(&robots[0], &["published"])];
    for (r, published) in robots.iter().zip(streams) {
        let c = &r["counters"];
        // The outage: the link was lost, and many samples never came.
        assert!(u(c, &["link_losses"]) >= 1, "{r}");
        assert!(u(c, &["received"]) + 50 < published, "{c} vs {published}");
        // Same leader all along, and it tracks again: converged at the end.
        assert_eq!(u(c, &["restarts"]), 0, "{c}");
        assert!(f(r, &["final_error"]) < 0.01, "{r}");
    }
    // The collector heard the robots again after the new router came up.
    assert!(u(&collector, &["received"]) > 0);
    let last = rows(&dir.path().join("trajectory.csv"))
        .iter()
        .map(|(t, _, _)| *t)
        .fold(0.0, f64::max);
    assert!(last > 55.0, "the collector's last row is at t = {last}");
    // Everyone came back through the second router.
    assert_eq!(u(&router_report, &["members_peak"]), 4, "{router_report}");
}

/// Two sites on loopback (`fleet up --sites 2`): two routers linked to each
/// other, robot 1 and the leader and collector on site 1, robot 2 on site 2.
/// Robot 2 follows robot 1 across the routers, and the collector on site 1
/// records robot 2: both converge.
#[test]
fn two_sites_two_routers_converge() {
    let _fleet = common::one_fleet_at_a_time();
    let dir = tempfile::tempdir().unwrap();
    let report = up(
        &fixture("fast-circle.toml"),
        dir.path(),
        &["--time-scale", "10", "--sites", "2"],
    );
    assert_eq!(report["topology"], "router");
    assert_eq!(report["routers"].as_array().unwrap().len(), 2);
    assert_eq!(
        report["sites"][0],
        serde_json::json!(["collector", "robot/1", "leader"])
    );
    assert_eq!(report["sites"][1], serde_json::json!(["robot/2"]));
    for r in report["routers"].as_array().unwrap() {
        // Every process's liveliness token reached both routers.
        assert_eq!(u(r, &["members_peak"]), 4, "{r}");
    }
    for k in 0..2 {
        let r = &report["robots"][k];
        assert!(f(r, &["final_error"]) < 1e-3, "{r}");
        assert_eq!(u(&r["counters"], &["link_losses"]), 0, "{r}");
    }
    assert!(
        u(
            &report["collector"],
            &["received_by_key", "echelon/fast-circle/robot/2/state"]
        ) > 1000
    );
}
