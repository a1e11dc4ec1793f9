#![allow(clippy::unwrap_used)] // tests fail loudly by design

use proptest::prelude::*;

use super::*;

const SCENARIO: &str = "[sim]\nduration = 5.0\ndt = 0.001\n[reference.circle]\nspeed = 0.1\nturn_rate = 0.1\nstart = { x = 0.0, y = 0.0, theta = 0.0 }\n[[agents]]\nstart = { x = -0.5, y = 0.0, theta = 0.0 }\nleader = \"reference\"\noffset = { x = 0.5, y = 0.0 }\n[[agents]]\nstart = { x = -1.0, y = 0.0, theta = 0.0 }\nleader = 1\noffset = { x = 0.5, y = 0.0 }\n";

fn file(agent: u32) -> RobotFile {
    RobotFile {
        version: ROBOT_FILE_VERSION,
        scenario: "scenario.toml".into(),
        scenario_sha256: sha256_hex(SCENARIO),
        agent,
        fleet: None,
        drive: Drive::Simulated,
        clock: ClockSection::default(),
        net: NetSection {
            mode: NetMode::Client,
            connect: vec!["tcp/127.0.0.2:7447".into()],
            listen: Vec::new(),
            zenoh_config: None,
        },
        secure: None,
        operator_token: Some("operator-token".into()),
        rehearsal: FaultSpec::default(),
    }
}

fn in_dir(text: &str) -> (tempfile::TempDir, PathBuf) {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("scenario.toml"), SCENARIO).unwrap();
    let path = dir.path().join(ROBOT_FILE);
    std::fs::write(&path, text).unwrap();
    (dir, path)
}

fn err(text: &str) -> String {
    match RobotFile::parse(text, "robot.toml") {
        Ok(f) => panic!("accepted: {f:?}"),
        Err(e) => e.to_string(),
    }
}

#[test]
fn sha256_is_the_standard_digest() {
    // FIPS 180-2's "abc" vector.
    assert_eq!(
        sha256_hex("abc"),
        "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad"
    );
}

#[test]
fn a_written_file_loads_into_the_robots_options() {
    let f = file(2);
    let (_dir, path) = in_dir(&f.to_toml(&["a header".into()]).unwrap());
    let loaded = RobotFile::load(&path).unwrap();
    assert_eq!(loaded.file, f);
    let o = loaded.options().unwrap();
    assert_eq!(o.agent, 2);
    assert!(!o.ros2);
    assert_eq!(o.process.net.connect, ["tcp/127.0.0.2:7447"]);
    assert_eq!(o.process.net.mode, Some(Mode::Client));
    assert!(o.operator_token.is_none() || std::env::var_os(crate::token::TOKEN_ENV).is_some());
}

#[test]
fn the_token_file_beside_it_is_the_robots_token() {
    let (dir, path) = in_dir(&file(1).to_toml(&[]).unwrap());
    let t = OperatorToken::random().unwrap();
    t.write_file(&dir.path().join("operator-token")).unwrap();
    let o = RobotFile::load(&path).unwrap().options().unwrap();
    assert_eq!(o.operator_token, Some(t));
}

#[test]
fn another_scenario_is_refused_naming_both_hashes() {
    let (dir, path) = in_dir(&file(1).to_toml(&[]).unwrap());
    std::fs::write(
        dir.path().join("scenario.toml"),
        SCENARIO.replace("speed = 0.1", "speed = 0.2"),
    )
    .unwrap();
    let e = RobotFile::load(&path)
        .unwrap()
        .options()
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("scenario_sha256") && e.contains("not the scenario"),
        "{e}"
    );
    assert_eq!(e.lines().count(), 1, "{e}");
}

#[test]
fn an_agent_the_scenario_lacks_is_refused() {
    let (_dir, path) = in_dir(&file(3).to_toml(&[]).unwrap());
    let e = RobotFile::load(&path)
        .unwrap()
        .options()
        .unwrap_err()
        .to_string();
    assert!(e.contains("agent: 3 is not an agent"), "{e}");
}

#[test]
fn bad_values_are_refused_at_their_field() {
    let good = file(1).to_toml(&[]).unwrap();
    let e = err(&good.replace("agent = 1", "agent = 1\nwheels = 2"));
    assert!(e.starts_with("robot.toml:") && e.contains("wheels"), "{e}");
    let e = err(&good.replace("tcp/127.0.0.2:7447", "tcp/127.0.0.2"));
    assert!(e.contains("net.connect"), "{e}");
    let e = err(&good.replace("agent = 1", "agent = 0"));
    assert!(e.contains("agent:"), "{e}");
    let e = err(&good.replace("version = 1", "version = 7"));
    assert!(e.contains("version"), "{e}");
    let e = err(&good.replace("drive = \"simulated\"", "drive = \"hover\""));
    assert!(e.contains("robot.toml:") && e.contains("hover"), "{e}");
    let mut ros = file(1);
    ros.drive = Drive::Ros2;
    ros.clock.time_scale = 4.0;
    let e = err(&ros.to_toml(&[]).unwrap());
    assert!(
        e.contains("clock.time_scale") && e.contains("real time"),
        "{e}"
    );
    let mut sec = file(2);
    sec.secure = Some(SecureSection {
        dir: "certs".into(),
        identity: "robot-1".into(),
        robots: 2,
    });
    let e = err(&sec.to_toml(&[]).unwrap());
    assert!(e.contains("secure.identity"), "{e}");
}

fn endpoint() -> impl Strategy<Value = String> {
    (
        prop::sample::select(vec!["tcp", "udp", "tls", "quic"]),
        1u8..=254,
        1u8..=254,
        1u16..,
    )
        .prop_map(|(p, a, b, port)| format!("{p}/10.{a}.{b}.1:{port}"))
}

fn any_file() -> impl Strategy<Value = RobotFile> {
    (
        1u32..200,
        prop::option::of("[a-z][a-z0-9_.-]{0,12}"),
        prop::sample::select(vec![Drive::Simulated, Drive::Ros2, Drive::Ros2Simulated]),
        (0.1f64..50.0, prop::option::of(0.5f64..1e4)),
        prop::collection::vec(endpoint(), 1..4),
        any::<bool>(),
        (
            prop::option::of((0.0f64..100.0, 0.01f64..10.0)),
            0.0f64..1.0,
            any::<u64>(),
        ),
    )
        .prop_map(
            |(agent, fleet, drive, (scale, duration), connect, secure, (outage, loss, seed))| {
                RobotFile {
                    version: ROBOT_FILE_VERSION,
                    scenario: "scenario.toml".into(),
                    scenario_sha256: sha256_hex(&format!("{agent}{fleet:?}")),
                    agent,
                    fleet,
                    drive,
                    clock: ClockSection {
                        time_scale: if drive == Drive::Ros2 { 1.0 } else { scale },
                        duration,
                        die_at: duration.map(|d| d / 2.0),
                    },
                    net: NetSection {
                        mode: NetMode::Client,
                        connect,
                        listen: Vec::new(),
                        zenoh_config: None,
                    },
                    secure: secure.then(|| SecureSection {
                        dir: "certs".into(),
                        identity: Member::Robot(agent).identity(),
                        robots: agent + 3,
                    }),
                    operator_token: None,
                    rehearsal: FaultSpec {
                        outage,
                        loss,
                        seed,
                        ..FaultSpec::default()
                    },
                }
            },
        )
}

proptest! {
    /// Any valid file written and read back is the same file, and writing
    /// it again gives the same bytes (bundles are reproducible).
    #[test]
    fn files_round_trip_byte_for_byte(f in any_file()) {
        let text = f.to_toml(&["header".into()]).unwrap();
        let back = RobotFile::parse(&text, "robot.toml").unwrap();
        prop_assert_eq!(&back, &f);
        prop_assert_eq!(back.to_toml(&["header".into()]).unwrap(), text);
    }
}
