//! `fleet up --ros2` on simulated ROS 2 bases: the robots end where the
//! simulator ends; a dead base's garbage odometry is refused and SIGTERM leaves
//! a zero `cmd_vel`.

use super::*;

/// The simulator's final poses of the scenario run for `duration`.
fn simulated_final(duration: &str, dir: &Path) -> Vec<(f64, f64)> {
    echelon_ok(&["run", SCENARIO, "--duration", duration, "--out"], dir);
    let s: Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("summary.json")).unwrap()).unwrap();
    s["agents"]
        .as_array()
        .unwrap()
        .iter()
        .map(|a| (f(a, &["final_pose", "x"]), f(a, &["final_pose", "y"])))
        .collect()
}

/// `fleet up --ros2`: every robot↔base message in ROS 2's format; the
/// robots end within 5 mm of the simulator's final positions (measured:
/// 0.25 mm at 30 s), and the collector recorded the ROS topics and each
/// robot's raw odometry ([`raw_odometry_is_what_the_base_published`]).
#[test]
fn fleet_up_ros2_ends_where_the_simulator_ends() {
    let _fleet = common::one_fleet_at_a_time();
    let dir = tempfile::tempdir().unwrap();
    let up = common::fleet_up(&UP_ROS2, dir.path());
    let sim = simulated_final("30", &dir.path().join("sim"));
    let robots = up["robots"].as_array().unwrap();
    assert_eq!(robots.len(), sim.len());
    for (r, (x, y)) in robots.iter().zip(&sim) {
        let st = r["final_state"].as_array().unwrap();
        let (rx, ry) = (st[0].as_f64().unwrap(), st[1].as_f64().unwrap());
        let d = (rx - x).hypot(ry - y);
        assert!(d < 5e-3, "robot {}: {d} m from the simulator", r["agent"]);
        assert!(f(r, &["final_error"]) < 5e-3, "{r}");
        drove_cleanly(&r["ros2"]);
    }
    for b in up["bases"].as_array().unwrap() {
        let c = &b["counters"];
        assert_eq!(f(c, &["cmd_received"]), f(c, &["cmd_accepted"]), "{b}");
        assert_eq!(b["last_command"], serde_json::json!([0.0, 0.0]), "{b}");
    }
    let col = &up["collector"];
    assert!(f(col, &["ros_recorded"]) > 1000.0, "{col}");
    assert_eq!(f(col, &["ros_refused"]), 0.0, "{col}");
    raw_odometry_is_what_the_base_published(dir.path());
}

/// Issue 22: the collector keeps each ROS 2 robot's raw odometry. In the
/// run's `fleet.mcap`, every `/agent/K/state` carries `odometry` (`raw`,
/// `age`, `fix_age`): `raw` is, bit for bit, the pose of an odometry
/// message its base published in its odom frame (`/robotK/odom`, as the
/// collector recorded it; the heading unwrapped), the world pose is
/// `odom_origin ⊕ raw` (no fixes: the origin is the agent's start), the
/// age is within the odometry timeout and `fix_age` is null. `odometry.csv`
/// has the same, one row per started state.
fn raw_odometry_is_what_the_base_published(dir: &Path) {
    use std::collections::BTreeMap;
    let scenario = echelon::scenario::Scenario::builtin(SCENARIO).unwrap();
    let links = scenario.fleet().unwrap().ros2;
    let bytes = std::fs::read(dir.join("fleet.mcap")).unwrap();
    // Per robot: odometry poses `[x, y, yaw]` as the base published them.
    let mut odom: BTreeMap<u32, Vec<[f64; 3]>> = BTreeMap::new();
    let mut states: Vec<(u32, Value)> = Vec::new();
    for m in mcap::MessageStream::new(&bytes).unwrap() {
        let m = m.unwrap();
        let topic = m.channel.topic.as_str();
        if let Some(k) = common::topic_number(topic, "/agent/", "/state") {
            states.push((k, serde_json::from_slice(&m.data).unwrap()));
        } else if let Some(k) = common::topic_number(topic, "/robot", "/odom") {
            let o = Odometry::from_cdr_finite(&m.data).unwrap();
            let p = o.pose.pose.position;
            odom.entry(k).or_default().push([p.x, p.y, o.yaw()]);
        }
    }
    for poses in odom.values_mut() {
        poses.sort_by(|a, b| a[0].total_cmp(&b[0]));
    }
    // The published odometry at `(x, y)` (to the last bit of a JSON
    // round trip): its yaw.
    let published = |k: u32, x: f64, y: f64| -> Option<f64> {
        let poses = &odom[&k];
        let close = |a: f64, b: f64| (a - b).abs() <= 1e-12 * (1.0 + b.abs());
        let from = poses.partition_point(|p| p[0] < x - 1e-9);
        poses[from..]
            .iter()
            .take_while(|p| p[0] <= x + 1e-9)
            .find(|p| close(p[0], x) && close(p[1], y))
            .map(|p| p[2])
    };
    assert_eq!(odom.len(), links.len(), "every base's odometry recorded");
    let mut checked = BTreeMap::new();
    for (k, v) in &states {
        let o = &v["odometry"];
        let raw: Vec<f64> = o["raw"]
            .as_array()
            .unwrap_or_else(|| panic!("robot {k}: no raw odometry in {v}"))
            .iter()
            .map(|x| x.as_f64().unwrap())
            .collect();
        let yaw = published(*k, raw[0], raw[1])
            .unwrap_or_else(|| panic!("robot {k}: raw {raw:?} is no odometry its base published"));
        assert!(
            echelon::model::wrap_angle(raw[2] - yaw).abs() < 1e-12,
            "robot {k}: raw heading {} against {yaw}",
            raw[2]
        );
        let link = &links[*k as usize - 1];
        let world = link.odom_origin.compose(&echelon::model::Pose {
            x: raw[0],
            y: raw[1],
            theta: raw[2],
        });
        let got = [f(v, &["x"]), f(v, &["y"]), f(v, &["theta"])];
        let want = [world.x, world.y, world.theta];
        for (g, w) in got.iter().zip(want) {
            assert!(
                (g - w).abs() < 1e-9,
                "robot {k}: world {got:?}, odom_origin ⊕ raw {want:?}"
            );
        }
        let age = f(o, &["age"]);
        assert!(
            (0.0..=link.odom_timeout).contains(&age),
            "robot {k}: age {age}"
        );
        assert!(o["fix_age"].is_null(), "robot {k}: {o}");
        // No `[odometry]`: its error is unknown, σ 0.
        assert_eq!(f(v, &["sigma"]), 0.0, "robot {k}");
        *checked.entry(*k).or_insert(0) += 1;
    }
    assert!(checked.values().all(|&n| n > 500), "{checked:?}");
    // The same in odometry.csv, one row per started state.
    let csv = std::fs::read_to_string(dir.join("odometry.csv")).unwrap();
    let mut lines = csv.lines();
    assert_eq!(
        lines.next(),
        Some("t,agent,x,y,theta,x_raw,y_raw,theta_raw,age,fix_age")
    );
    let mut rows = 0;
    for line in lines {
        let cells: Vec<&str> = line.split(',').collect();
        assert_eq!(cells.len(), 10, "{line}");
        assert_eq!(cells[9], "", "no fix: {line}");
        let n: Vec<f64> = cells[..9].iter().map(|c| c.parse().unwrap()).collect();
        let k = n[1] as u32;
        assert!(published(k, n[5], n[6]).is_some(), "{line}");
        let world = links[k as usize - 1]
            .odom_origin
            .compose(&echelon::model::Pose {
                x: n[5],
                y: n[6],
                theta: n[7],
            });
        assert!(
            (world.x - n[2]).abs() < 1e-9 && (world.y - n[3]).abs() < 1e-9,
            "{line}"
        );
        rows += 1;
    }
    assert!(rows > 1000, "{rows} rows");
}

/// Robot 1 drives a simulated base; the base dies and the test then puts
/// garbage, truncated CDR, NaN poses and a wrong type hash on the odom
/// topic: each is counted and refused and the robot commands zero and holds.
/// SIGTERM then leaves a zero `cmd_vel` as the last message on its key.
#[test]
fn bad_odometry_is_refused_and_sigterm_leaves_zero_on_cmd_vel() {
    let _fleet = common::one_fleet_at_a_time();
    let e = ports(4);
    let session = common::open_peer(&e);
    let heard: Heard = Arc::default();
    let h = heard.clone();
    let cmd_key = "0/robot1/cmd_vel/**";
    let _sub = session
        .declare_subscriber(cmd_key)
        .callback(move |s| {
            let m = TwistStamped::from_cdr_finite(&s.payload().to_bytes()).unwrap();
            h.lock()
                .unwrap()
                .push((m.twist.linear.x, m.twist.angular.z));
        })
        .wait()
        .unwrap();
    let base = spawn_peer(
        &["fleet", "base", SCENARIO, "--ros2", "--agent", "1"],
        &e,
        1,
    );
    let robot = spawn_peer(
        &["fleet", "robot", SCENARIO, "--ros2", "--agent", "1"],
        &e,
        2,
    );
    let _leader = spawn_peer(
        &[
            "fleet",
            "leader",
            SCENARIO,
            "--wait-for",
            "robot/1",
            "--wait-for",
            "base/1",
        ],
        &e,
        3,
    );
    // Until the robot drives (a non-zero command).
    let start = Instant::now();
    while !heard
        .lock()
        .unwrap()
        .iter()
        .any(|&(v, w)| v != 0.0 || w != 0.0)
    {
        assert!(
            start.elapsed() < Duration::from_secs(30),
            "robot 1 never moved"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
    std::thread::sleep(Duration::from_secs(1));
    base.terminate();
    let base_report = base.report();
    assert!(
        f(&base_report, &["counters", "cmd_accepted"]) > 10.0,
        "{base_report}"
    );

    // Only bad odometry from now on.
    let odom_key = topic_key(
        echelon_ros2::KeyScheme::RmwZenoh,
        0,
        "/robot1/odom",
        &ODOMETRY,
    );
    let at_x =
        |x| Odometry::planar(x, -0.6, 1.5, 0.0, 0.0, Time::default(), "odom", "base_link").to_cdr();
    let (good, nan) = (at_x(0.0), at_x(f64::NAN));
    let wrong_type = topic_key(echelon_ros2::KeyScheme::RmwZenoh, 0, "/robot1/odom", &TWIST);
    let mut sent = 0;
    let garbage_from = heard.lock().unwrap().len();
    for _ in 0..20 {
        session.put(&odom_key, b"garbage".to_vec()).wait().unwrap();
        session.put(&odom_key, good[..40].to_vec()).wait().unwrap();
        session.put(&odom_key, nan.clone()).wait().unwrap();
        session.put(&wrong_type, good.clone()).wait().unwrap();
        sent += 1;
        std::thread::sleep(Duration::from_millis(50));
    }
    // The odometry went stale 0.5 s after the base died: zero ever since
    // (allowing the in-flight commands of that half second).
    let after: Vec<_> = heard.lock().unwrap()[garbage_from..].to_vec();
    let tail = &after[after.len() / 2..];
    assert!(
        !tail.is_empty() && tail.iter().all(|&c| c == (0.0, 0.0)),
        "{tail:?}"
    );

    robot.terminate();
    let report = robot.report();
    std::thread::sleep(Duration::from_millis(300));
    let ros = &report["ros2"];
    for k in ["odom_malformed", "odom_non_finite", "odom_wrong_type"] {
        assert!(
            f(ros, &[k]) >= f64::from(sent) * if k == "odom_malformed" { 2.0 } else { 1.0 } - 2.0,
            "{k}: {ros}"
        );
    }
    assert!(f(ros, &["cmd_zero"]) > 0.0);
    let last = *heard.lock().unwrap().last().unwrap();
    assert_eq!(last, (0.0, 0.0), "the last cmd_vel after SIGTERM");
}
