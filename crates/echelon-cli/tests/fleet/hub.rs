//! A lab fleet across machines, on loopback addresses of their own: the
//! hub (`fleet up --hub`) listening on 127.0.0.2, an on-board robot
//! (`fleet robot --config`, from `fleet bundle`) reaching it from
//! 127.0.0.3. The reference starts only once every robot joined; a wait
//! that expires names the missing robots; bundles are reproducible; a
//! robot file refuses what it was not made for.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

use super::{EXE, Guard, check, fixture, rows, spawn};
use crate::common::{fleet_summary, one_fleet_at_a_time};

/// A free TCP port on `ip` (bound then released).
fn free_port(ip: &str) -> u16 {
    std::net::TcpListener::bind((ip, 0))
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

/// fast-circle (two robots, robot 2 behind robot 1) with robot 2 on-board,
/// written into `dir`; its path.
fn onboard_scenario(dir: &Path) -> PathBuf {
    let src = std::fs::read_to_string(fixture("fast-circle.toml")).unwrap();
    let (head, tail) = src.split_at(src.rfind("[[agents]]").unwrap());
    let path = dir.join("lab.toml");
    std::fs::write(
        &path,
        format!(
            "{head}{}",
            tail.replacen("leader = 1\n", "leader = 1\nplacement = \"onboard\"\n", 1)
        ),
    )
    .unwrap();
    path
}

/// Every file under `dir`, by relative path, with its bytes.
fn tree(dir: &Path) -> Vec<(PathBuf, Vec<u8>)> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                stack.push(p);
            } else {
                out.push((
                    p.strip_prefix(dir).unwrap().to_path_buf(),
                    std::fs::read(&p).unwrap(),
                ));
            }
        }
    }
    out.sort();
    out
}

fn bundle(scenario: &Path, hub: &str, out: &Path, extra: &[&str]) -> std::process::Output {
    Command::new(EXE)
        .args(["fleet", "bundle"])
        .arg(scenario)
        .args(["--hub", hub, "--out"])
        .arg(out)
        .args(extra)
        .output()
        .unwrap()
}

fn stderr(o: &std::process::Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// One line, exit `code`.
fn refused(o: &std::process::Output, code: i32, what: &str) -> String {
    let e = stderr(o);
    assert_eq!(o.status.code(), Some(code), "{what}: {e}");
    assert_eq!(e.trim_end().lines().count(), 1, "{what}: {e}");
    e
}

#[test]
fn a_hub_waits_for_its_late_onboard_robot_which_joins_from_its_bundle_and_converges() {
    let _slot = one_fleet_at_a_time();
    let dir = tempfile::tempdir().unwrap();
    let scenario = onboard_scenario(dir.path());
    let port = free_port("127.0.0.2");
    let hub = format!("tcp/127.0.0.2:{port}");
    // Same scenario and options, same bytes.
    let (b1, b2) = (dir.path().join("b1"), dir.path().join("b2"));
    for b in [&b1, &b2] {
        let o = bundle(&scenario, &hub, b, &["--simulated", "--time-scale", "5"]);
        check(&o, "fleet bundle");
    }
    let files = tree(&b1);
    assert_eq!(files, tree(&b2), "bundles differ");
    let names: Vec<String> = files.iter().map(|(p, _)| p.display().to_string()).collect();
    assert_eq!(
        names,
        [
            "robot-2/echelon-robot-2.service",
            "robot-2/echelon-robot.sh",
            "robot-2/robot.toml",
            "robot-2/scenario.toml"
        ],
        "only the on-board robot is bundled"
    );
    assert_eq!(
        std::fs::read(b1.join("robot-2/scenario.toml")).unwrap(),
        std::fs::read(&scenario).unwrap()
    );

    let out = dir.path().join("hub");
    let mut up = Guard(
        Command::new(EXE)
            .args(["fleet", "up"])
            .arg(&scenario)
            .args(["--hub", "--listen", &hub, "--wait", "90"])
            .args(["--time-scale", "5", "--duration", "30", "--out"])
            .arg(&out)
            .stdout(std::process::Stdio::piped())
            .stderr(std::process::Stdio::piped())
            .spawn()
            .unwrap(),
    );
    // Robot 2 joins late: well after robot 1 (on the hub) has.
    std::thread::sleep(Duration::from_secs(4));
    assert!(matches!(up.0.try_wait(), Ok(None)), "the hub gave up early");
    assert!(
        !out.join("logs/leader.log").exists(),
        "the leader started before every robot joined"
    );
    let joined_at = Instant::now();
    let robot = spawn(&[
        "fleet",
        "robot",
        "--config",
        b1.join("robot-2/robot.toml").to_str().unwrap(),
        "--hub",
        &format!("{hub}#bind=127.0.0.3:0"),
    ]);
    // Every command reaches the hub by the endpoint it printed: the
    // running fleet's status, from "another machine".
    std::thread::sleep(Duration::from_secs(3));
    let o = Command::new(EXE)
        .args(["fleet", "status"])
        .arg(&scenario)
        .args(["--hub", &hub, "--json"])
        .output()
        .unwrap();
    check(&o, "fleet status --hub");
    let status: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let states: Vec<String> = status["robots"]
        .as_array()
        .unwrap()
        .iter()
        .map(|r| r["state"].as_str().unwrap_or_default().to_owned())
        .collect();
    assert_eq!(states, ["running", "running"], "{status}");
    let status = loop {
        if let Some(s) = up.0.try_wait().unwrap() {
            break s;
        }
        assert!(
            joined_at.elapsed() < Duration::from_secs(120),
            "the hub did not finish"
        );
        std::thread::sleep(Duration::from_millis(100));
    };
    let mut err = String::new();
    std::io::Read::read_to_string(&mut up.0.stderr.take().unwrap(), &mut err).unwrap();
    assert!(status.success(), "{err}");
    assert!(
        err.contains("robot/2 (on-board") && err.contains("joined after"),
        "no join line: {err}"
    );
    assert!(
        err.contains("from 127.0.0.3"),
        "the join line names no address: {err}"
    );
    robot.terminate();
    let summary = fleet_summary(&out);
    // The leader's clock started after robot 2 was started.
    let clock = summary["leader"]["clock_start_unix_ns"].as_u64().unwrap();
    let startup = summary["startup"].as_f64().unwrap();
    assert!(
        startup > 4.0,
        "the reference started {startup} s in, before robot 2 joined"
    );
    assert!(clock > 0);
    // Robot 2 (on-board, following robot 1) converged in the hub's log.
    let tail: Vec<f64> = rows(&out.join("trajectory.csv"))
        .into_iter()
        .filter(|(t, a, _)| *a == 2 && (28.0..30.0).contains(t))
        .map(|(_, _, v)| v[5].hypot(v[6]))
        .collect();
    assert!(tail.len() > 10, "robot 2 was not logged at the end");
    let worst = tail.iter().copied().fold(0.0, f64::max);
    assert!(worst < 0.01, "robot 2's ‖e‖ reached {worst} m at the end");
}

#[test]
fn an_expired_wait_names_the_missing_onboard_robot_and_nothing_moves() {
    let _slot = one_fleet_at_a_time();
    let dir = tempfile::tempdir().unwrap();
    let scenario = onboard_scenario(dir.path());
    let hub = format!("tcp/127.0.0.2:{}", free_port("127.0.0.2"));
    let out = dir.path().join("hub");
    let started = Instant::now();
    let o = Command::new(EXE)
        .args(["fleet", "up"])
        .arg(&scenario)
        .args(["--hub", "--listen", &hub, "--wait", "3", "--out"])
        .arg(&out)
        .output()
        .unwrap();
    let e = stderr(&o);
    assert_eq!(o.status.code(), Some(1), "{e}");
    assert!(started.elapsed() < Duration::from_secs(40), "{e}");
    let last = e.trim_end().lines().last().unwrap();
    assert!(
        last.contains("waited 3 s")
            && last.contains("robot/2 (on-board)")
            && !last.contains("robot/1"),
        "{e}"
    );
    // The leader never started: no reference was published.
    assert!(!out.join("logs/leader.log").exists(), "{e}");
    assert!(!out.join("fleet-summary.json").exists());
}

#[test]
fn a_robot_file_refuses_what_it_was_not_made_for_in_one_line() {
    let dir = tempfile::tempdir().unwrap();
    let scenario = onboard_scenario(dir.path());
    let b = dir.path().join("b");
    check(
        &bundle(&scenario, "tcp/127.0.0.2:7447", &b, &["--simulated"]),
        "bundle",
    );
    let file = b.join("robot-2/robot.toml");
    let text = std::fs::read_to_string(&file).unwrap();
    let run = |path: &Path, extra: &[&str]| {
        Command::new(EXE)
            .args(["fleet", "robot", "--config"])
            .arg(path)
            .args(extra)
            .output()
            .unwrap()
    };
    // An agent the scenario does not have.
    let other = b.join("robot-2/robot-9.toml");
    std::fs::write(&other, text.replace("agent = 2", "agent = 9")).unwrap();
    let e = refused(&run(&other, &[]), 2, "unknown agent");
    assert!(e.contains("agent: 9 is not an agent"), "{e}");
    // A bundle for another scenario: its hash does not match.
    let scen = b.join("robot-2/scenario.toml");
    let original = std::fs::read_to_string(&scen).unwrap();
    std::fs::write(&scen, original.replace("speed = 0.2", "speed = 0.25")).unwrap();
    let e = refused(&run(&file, &[]), 2, "hash mismatch");
    assert!(
        e.contains("scenario_sha256") && e.contains("fleet bundle"),
        "{e}"
    );
    std::fs::write(&scen, &original).unwrap();
    // An endpoint that cannot be parsed.
    let e = refused(&run(&file, &["--hub", "tcp/127.0.0.2"]), 2, "bad endpoint");
    assert!(e.contains("no port"), "{e}");
    let bad = b.join("robot-2/bad-net.toml");
    std::fs::write(
        &bad,
        text.replace("tcp/127.0.0.2:7447", "tcp/127.0.0.2:http"),
    )
    .unwrap();
    let e = refused(&run(&bad, &[]), 2, "bad endpoint in the file");
    assert!(e.contains("net.connect"), "{e}");
    // Unknown fields, at their line.
    let unknown = b.join("robot-2/unknown.toml");
    std::fs::write(&unknown, text.replace("agent = 2", "agent = 2\nspeed = 3")).unwrap();
    let e = refused(&run(&unknown, &[]), 2, "unknown field");
    assert!(e.contains("unknown.toml:") && e.contains("speed"), "{e}");
    // Only --hub may come with --config.
    let e = refused(&run(&file, &["--time-scale", "2"]), 2, "extra flags");
    assert!(e.contains("only --hub"), "{e}");
    // A hub that never answers: a timeout, exit 1, naming it.
    let nobody = format!("tcp/127.0.0.2:{}", free_port("127.0.0.2"));
    let e = refused(&run(&file, &["--hub", &nobody]), 1, "no hub");
    assert!(e.contains(&nobody) && e.contains("no answer"), "{e}");
}

#[test]
fn bundle_and_hub_refuse_bad_input_before_anything_is_written() {
    let dir = tempfile::tempdir().unwrap();
    let scenario = onboard_scenario(dir.path());
    // A scenario with no on-board robot: nothing to bundle unless --all.
    let b = dir.path().join("none");
    let e = refused(
        &bundle(
            Path::new(&fixture("fast-circle.toml")),
            "tcp/10.0.0.1:7447",
            &b,
            &[],
        ),
        2,
        "no on-board robot",
    );
    assert!(e.contains("placement") && e.contains("--all"), "{e}");
    assert!(!b.exists());
    let all = dir.path().join("all");
    check(
        &bundle(
            Path::new(&fixture("fast-circle.toml")),
            "tcp/10.0.0.1:7447",
            &all,
            &["--all"],
        ),
        "bundle --all",
    );
    assert!(all.join("robot-1/robot.toml").is_file() && all.join("robot-2/robot.toml").is_file());
    // Real robots run in real time.
    let e = refused(
        &bundle(&scenario, "tcp/10.0.0.1:7447", &b, &["--time-scale", "4"]),
        2,
        "time scale without --simulated",
    );
    assert!(e.contains("--simulated"), "{e}");
    // Secure mode with certificates missing: nothing written.
    let e = refused(
        &bundle(
            &scenario,
            "quic/10.0.0.1:7447",
            &b,
            &["--secure", dir.path().join("nope").to_str().unwrap()],
        ),
        2,
        "missing certificates",
    );
    assert!(e.contains("fleet certs"), "{e}");
    assert!(!b.exists());
    // On-board robots need the hub mode; the hub a known port.
    let up = |extra: &[&str]| {
        Command::new(EXE)
            .args(["fleet", "up"])
            .arg(&scenario)
            .args(["--out", dir.path().join("up").to_str().unwrap()])
            .args(extra)
            .output()
            .unwrap()
    };
    let e = refused(&up(&[]), 2, "on-board without --hub");
    assert!(e.contains("agents 2") && e.contains("--hub"), "{e}");
    let e = refused(&up(&["--hub", "--listen", "tcp/127.0.0.2:0"]), 2, "port 0");
    assert!(e.contains("known port"), "{e}");
    let e = refused(
        &up(&["--hub", "--listen", "tcp/127.0.0.2:7447", "--ros2"]),
        2,
        "bases",
    );
    assert!(e.contains("--simulated"), "{e}");
    assert!(!dir.path().join("up").exists());
}

#[test]
fn a_secure_bundle_holds_only_its_robots_own_key() {
    let dir = tempfile::tempdir().unwrap();
    let scenario = onboard_scenario(dir.path());
    let certs = crate::common::certs(dir.path(), 2);
    let b = dir.path().join("b");
    let token = dir.path().join("token");
    std::fs::write(&token, "00112233445566778899aabbccddeeff").unwrap();
    check(
        &bundle(
            &scenario,
            "quic/10.0.0.1:7447",
            &b,
            &[
                "--secure",
                certs.to_str().unwrap(),
                "--token-file",
                token.to_str().unwrap(),
            ],
        ),
        "secure bundle",
    );
    let names: Vec<String> = tree(&b)
        .iter()
        .map(|(p, _)| p.display().to_string())
        .collect();
    assert!(
        names.contains(&"robot-2/certs/robot-2-key.pem".to_owned()),
        "{names:?}"
    );
    assert!(
        names.contains(&"robot-2/certs/ca.pem".to_owned()),
        "{names:?}"
    );
    assert!(
        !names
            .iter()
            .any(|n| n.contains("ca-key") || n.contains("robot-1") || n.contains("leader")),
        "another member's key: {names:?}"
    );
    use std::os::unix::fs::PermissionsExt;
    for private in ["robot-2/certs/robot-2-key.pem", "robot-2/operator-token"] {
        let mode = std::fs::metadata(b.join(private))
            .unwrap()
            .permissions()
            .mode();
        assert_eq!(mode & 0o077, 0, "{private} is readable by others");
    }
    let text = std::fs::read_to_string(b.join("robot-2/robot.toml")).unwrap();
    assert!(text.contains("identity = \"robot-2\""), "{text}");
}

#[test]
fn a_secure_hub_over_quic_takes_its_onboard_robot_from_a_secure_bundle() {
    let _slot = one_fleet_at_a_time();
    let dir = tempfile::tempdir().unwrap();
    let scenario = onboard_scenario(dir.path());
    let certs = dir.path().join("certs");
    check(
        &Command::new(EXE)
            .args(["fleet", "certs"])
            .arg(&certs)
            .args(["--robots", "2", "--host", "127.0.0.2"])
            .output()
            .unwrap(),
        "fleet certs",
    );
    let port = std::net::UdpSocket::bind(("127.0.0.2", 0))
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    let hub = format!("quic/127.0.0.2:{port}");
    let token = dir.path().join("operator-token");
    std::fs::write(&token, "00112233445566778899aabbccddeeff").unwrap();
    let b = dir.path().join("b");
    let secure = [
        "--secure",
        certs.to_str().unwrap(),
        "--token-file",
        token.to_str().unwrap(),
    ];
    check(
        &bundle(
            &scenario,
            &hub,
            &b,
            &[&["--simulated", "--time-scale", "5"][..], &secure].concat(),
        ),
        "secure bundle",
    );
    let out = dir.path().join("hub");
    let up = std::thread::spawn({
        let (scenario, out, hub) = (scenario.clone(), out.clone(), hub.clone());
        let secure: Vec<String> = secure.iter().map(|s| (*s).to_owned()).collect();
        move || {
            Command::new(EXE)
                .args(["fleet", "up"])
                .arg(&scenario)
                .args(["--hub", "--listen", &hub, "--wait", "60"])
                .args(&secure)
                .args(["--time-scale", "5", "--duration", "15", "--out"])
                .arg(&out)
                .output()
                .unwrap()
        }
    });
    std::thread::sleep(Duration::from_secs(2));
    let robot = spawn(&[
        "fleet",
        "robot",
        "--config",
        b.join("robot-2/robot.toml").to_str().unwrap(),
    ]);
    let o = up.join().unwrap();
    check(&o, "secure fleet up --hub");
    robot.terminate();
    let err = stderr(&o);
    assert!(
        err.contains("robot/2 (on-board") && err.contains("joined"),
        "{err}"
    );
    let tail: Vec<f64> = rows(&out.join("trajectory.csv"))
        .into_iter()
        .filter(|(t, a, _)| *a == 2 && (13.0..15.0).contains(t))
        .map(|(_, _, v)| v[5].hypot(v[6]))
        .collect();
    assert!(
        tail.len() > 10 && tail.iter().all(|e| *e < 0.01),
        "{tail:?}"
    );
}
