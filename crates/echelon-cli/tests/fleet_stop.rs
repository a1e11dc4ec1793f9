//! One stop for the whole fleet, as processes: `fleet up --ros2` runs;
//! `fleet stop` puts the fleet command and returns once every robot has
//! acknowledged it; within 50 ms of its publication the last `cmd_vel` of
//! every base is zero and nothing else follows until `fleet resume`, after
//! which every robot drives again. A resume needs the operator token `fleet
//! up` wrote (`OUT/operator-token`): without it nothing is put, with
//! another one the robots refuse it, in both cases exit 2 and every robot
//! stays stopped.

#![allow(clippy::unwrap_used)]

use std::collections::BTreeMap;
use std::path::Path;
use std::process::Command;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use serde_json::Value;
use zenoh::Wait;

use echelon_ros2::msgs::{RosMessage, TwistStamped};

mod common;

use common::{EXE, check, f, spawn};

const SCENARIO: &str = "experiment-circle-velocity";

/// What the test heard on the bases' `cmd_vel`: per namespace, `(UNIX ns
/// of arrival, v, ω)` in order.
type Heard = Arc<Mutex<BTreeMap<String, Vec<(u64, f64, f64)>>>>;

fn unix_ns() -> u64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .unwrap()
        .as_nanos() as u64
}

/// The environment variable `fleet resume` reads the operator token from.
const TOKEN_ENV: &str = "ECHELON_OPERATOR_TOKEN";

/// Runs `fleet stop` or `fleet resume` for `scenario` through `router`
/// with `more` arguments (no operator token in its environment): its exit
/// code, its report, its stderr.
fn run_command(what: &str, scenario: &str, router: &str, more: &[&str]) -> (i32, Value, String) {
    let out = Command::new(EXE)
        .args(["fleet", what, scenario, "--mode", "client", "--connect"])
        .arg(router)
        .args(["--reason", "fleet_stop test"])
        .args(more)
        .env_remove(TOKEN_ENV)
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&out.stdout);
    let report = text
        .lines()
        .rfind(|l| l.starts_with('{'))
        .map_or(Value::Null, |l| serde_json::from_str(l).unwrap());
    (
        out.status.code().unwrap_or(-1),
        report,
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// Runs `fleet stop` or `fleet resume` through `router` with `more`
/// arguments (no operator token in its environment); its report.
fn command(what: &str, router: &str, more: &[&str]) -> Value {
    let out = Command::new(EXE)
        .args(["fleet", what, SCENARIO, "--mode", "client", "--connect"])
        .arg(router)
        .args(["--reason", "fleet_stop test", "--timeout", "5"])
        .args(more)
        .env_remove(TOKEN_ENV)
        .output()
        .unwrap();
    check(&out, &format!("fleet {what}"));
    let text = String::from_utf8_lossy(&out.stdout);
    serde_json::from_str(text.lines().rfind(|l| l.starts_with('{')).unwrap()).unwrap()
}

/// `fleet up`'s operator token file in `out`, as an argument.
fn token_file(out: &Path) -> String {
    out.join("operator-token").to_str().unwrap().to_owned()
}

/// A resume with `more` arguments refused (exit 2) for want of the right
/// operator token: none given (`wrong` false: refused before anything is
/// put, no report) or a wrong one (put, and refused by both robots, named
/// with the reason).
fn refused_resume(scenario: &str, router: &str, more: &[&str], wrong: bool) -> Value {
    let (code, report, err) = run_command("resume", scenario, router, more);
    assert_eq!(code, 2, "{report} {err}");
    if !wrong {
        assert!(
            err.contains("fleet resume needs the operator token: give --token-file OUT/operator-token (written by fleet up), --token, or ECHELON_OPERATOR_TOKEN"),
            "{err}"
        );
        assert_eq!(report, Value::Null, "nothing put: {report}");
    } else {
        for k in 1..=2 {
            let why = format!("robot/{k} refused resume");
            assert!(err.contains(&why), "{err}");
        }
        assert!(err.contains("no valid operator token"), "{err}");
        assert_eq!(report["acknowledged"], serde_json::json!([]), "{report}");
        assert_eq!(report["refused"].as_array().unwrap().len(), 2, "{report}");
        assert_eq!(report["leader"], false, "{report}");
    }
    report
}

/// Another token than the fleet's.
const WRONG_TOKEN: &str = "0123456789abcdef0123456789abcdef";

/// Waits for `fleet up` to end successfully; its summary.
fn up_summary(up: common::Guard, dir: &Path) -> Value {
    let mut up = up;
    let status = up.0.wait().unwrap();
    let mut err = String::new();
    std::io::Read::read_to_string(&mut up.0.stderr.take().unwrap(), &mut err).unwrap();
    assert!(status.success(), "fleet up: {status}: {err}");
    common::fleet_summary(dir)
}

/// Waits until `heard` has a non-zero command after `since` from each of
/// `n` bases.
fn until_all_move(heard: &Heard, n: usize, since: u64, what: &str) {
    let start = Instant::now();
    loop {
        let moving = heard
            .lock()
            .unwrap()
            .values()
            .filter(|c| {
                c.iter()
                    .any(|&(t, v, w)| t > since && (v != 0.0 || w != 0.0))
            })
            .count();
        if moving == n {
            return;
        }
        assert!(
            start.elapsed() < Duration::from_secs(30),
            "{what}: {moving} of {n} bases moving"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// Starts `echelon fleet up SCENARIO EXTRA… --time-scale 2 --duration
/// DURATION --quiet --out OUT`; it and its router's endpoint.
fn fleet_up(scenario: &str, extra: &[&str], duration: &str, out: &Path) -> (common::Guard, String) {
    let up = spawn(
        &[
            &["fleet", "up", scenario],
            extra,
            &["--time-scale", "2", "--duration", duration, "--quiet"],
            &["--out", out.to_str().unwrap()],
        ]
        .concat(),
    );
    (up, router_endpoint(out))
}

fn router_endpoint(dir: &Path) -> String {
    let path = dir.join("endpoints.json");
    let start = Instant::now();
    loop {
        if let Ok(text) = std::fs::read_to_string(&path)
            && let Ok(v) = serde_json::from_str::<Value>(&text)
            && let Some(e) = v["router/1"].as_str()
        {
            return e.to_owned();
        }
        assert!(
            start.elapsed() < Duration::from_secs(30),
            "no endpoints.json"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// `fleet up --ros2` (×2), `fleet stop`, `fleet resume`: every robot
/// acknowledges each; from 50 ms after the stop's publication to the
/// resume every `cmd_vel` of every base is zero, the last one before that
/// instant too; after the resume every base moves again; the robots count
/// one stop and one resume, the leader paused, the collector logged both
/// commands.
#[test]
fn fleet_stop_zeroes_every_cmd_vel_until_fleet_resume() {
    let _fleet = common::one_fleet_at_a_time();
    let dir = tempfile::tempdir().unwrap();
    let (up, router) = fleet_up(SCENARIO, &["--ros2"], "24", dir.path());
    let session = echelon_fleet::net::open(&echelon_fleet::net::NetOptions {
        mode: Some(echelon_fleet::net::Mode::Client),
        connect: vec![router.clone()],
        ..Default::default()
    })
    .unwrap();
    let heard: Heard = Arc::default();
    let h = heard.clone();
    let _sub = session
        .declare_subscriber("0/*/cmd_vel/**")
        .callback(move |s| {
            let at = unix_ns();
            let ns = s.key_expr().as_str().split('/').nth(1).unwrap().to_owned();
            let m = TwistStamped::from_cdr_finite(&s.payload().to_bytes()).unwrap();
            h.lock().unwrap().entry(ns).or_default().push((
                at,
                m.twist.linear.x,
                m.twist.angular.z,
            ));
        })
        .wait()
        .unwrap();
    let n = 2;
    until_all_move(&heard, n, 0, "before the stop");
    std::thread::sleep(Duration::from_millis(500));

    // A stop needs no token.
    let stop = command("stop", &router, &[]);
    let robots: Vec<String> = (1..=n).map(|k| format!("robot/{k}")).collect();
    assert_eq!(stop["command"]["order"], "stop", "{stop}");
    assert_eq!(stop["alive"], serde_json::json!(robots), "{stop}");
    assert_eq!(stop["missing"], serde_json::json!([]), "{stop}");
    assert_eq!(stop["acknowledged"].as_array().unwrap().len(), n, "{stop}");
    assert_eq!(stop["leader"], true, "{stop}");
    let stopped_at = stop["published_unix_ns"].as_u64().unwrap();
    std::thread::sleep(Duration::from_millis(500));
    // Resumes without the fleet's token: refused, every base still at
    // zero (checked below: zero from the stop to the good resume).
    refused_resume(SCENARIO, &router, &[], false);
    let wrong = refused_resume(SCENARIO, &router, &["--token", WRONG_TOKEN], true);
    assert!(wrong["command"]["proof"].is_string(), "{wrong}");
    std::thread::sleep(Duration::from_millis(500));

    let resume = command(
        "resume",
        &router,
        &["--token-file", &token_file(dir.path())],
    );
    assert_eq!(resume["missing"], serde_json::json!([]), "{resume}");
    assert_eq!(resume["acknowledged"].as_array().unwrap().len(), n);
    let resumed_at = resume["published_unix_ns"].as_u64().unwrap();
    assert!(
        resume["command"]["seq"].as_u64() > stop["command"]["seq"].as_u64(),
        "{resume}"
    );
    until_all_move(&heard, n, resumed_at, "after the resume");

    let deadline = stopped_at + 50_000_000;
    for (ns, cmds) in heard.lock().unwrap().iter() {
        let last_by_deadline = cmds.iter().rev().find(|c| c.0 <= deadline).unwrap();
        assert_eq!(
            (last_by_deadline.1, last_by_deadline.2),
            (0.0, 0.0),
            "{ns}: the last cmd_vel 50 ms after the stop"
        );
        let held: Vec<_> = cmds
            .iter()
            .filter(|c| c.0 > deadline && c.0 < resumed_at)
            .collect();
        // Zero every control period (100 Hz at ×2) for 1.5 s and more.
        assert!(held.len() > 100, "{ns}: {}", held.len());
        assert!(
            held.iter().all(|c| (c.1, c.2) == (0.0, 0.0)),
            "{ns}: a non-zero cmd_vel before the resume"
        );
        // Zero within 50 ms: the first zero after the stop, measured.
        let first_zero = cmds
            .iter()
            .find(|c| c.0 >= stopped_at && (c.1, c.2) == (0.0, 0.0))
            .unwrap();
        eprintln!(
            "{ns}: first zero cmd_vel {:.1} ms after the stop's publication",
            (first_zero.0 as f64 - stopped_at as f64) * 1e-6
        );
    }

    let up = up_summary(up, dir.path());
    for r in up["robots"].as_array().unwrap() {
        let c = &r["commands"];
        assert_eq!((f(c, &["stops"]), f(c, &["resumes"])), (1.0, 1.0), "{r}");
        assert_eq!(f(c, &["refused"]), 0.0, "{r}");
        assert_eq!(f(c, &["unauthorized"]), 1.0, "{r}");
        assert_eq!(r["link"], "tracking", "{r}");
    }
    let leader = &up["leader"];
    assert!(f(leader, &["paused"]) > 2.0, "{leader}");
    assert_eq!(leader["stopped_the_fleet"], false, "{leader}");
    assert_eq!(f(&leader["commands"], &["unauthorized"]), 1.0, "{leader}");
    let col = &up["collector"];
    // The stop, the resume with the wrong token, the resume.
    assert_eq!(col["logged_by_topic"]["/fleet/command"], 3, "{col}");
    assert_eq!(col["rejected"], serde_json::json!({}), "{col}");
}

/// Secure mode: a stop put with robot 1's certificate is refused by the
/// router's access control (no robot stops, the command exits 1 naming
/// both robots); the same with the `operator` certificate `fleet certs`
/// makes stops both, and the resume lifts it.
#[test]
fn in_secure_mode_only_the_operator_stops_the_fleet() {
    let _fleet = common::one_fleet_at_a_time();
    let dir = tempfile::tempdir().unwrap();
    let certs = dir.path().join("certs");
    let certs = certs.to_str().unwrap();
    common::echelon_ok(&["fleet", "certs", "--robots", "2"], Path::new(certs));
    let scenario = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fleet/fast-circle.toml");
    let scenario = scenario.to_str().unwrap();
    let out = dir.path().join("up");
    let (up, router) = fleet_up(scenario, &["--secure", certs], "16", &out);
    let secure = |id: &'static str| ["--secure", certs, "--identity", id, "--timeout", "2"];
    // Wait until both robots have joined and hear their leader.
    let start = Instant::now();
    let (code, rogue, err) = loop {
        let (code, report, err) = run_command("stop", scenario, &router, &secure("robot-1"));
        if report["alive"].as_array().is_some_and(|a| a.len() == 2) {
            break (code, report, err);
        }
        assert!(start.elapsed() < Duration::from_secs(30), "{report} {err}");
        std::thread::sleep(Duration::from_millis(200));
    };
    assert_eq!(code, 1, "{rogue}");
    assert!(err.contains("did not acknowledge"), "{err}");
    assert_eq!(rogue["acknowledged"], serde_json::json!([]), "{rogue}");
    assert_eq!(rogue["missing"], serde_json::json!(["robot/1", "robot/2"]));

    let (code, stop, err) = run_command("stop", scenario, &router, &secure("operator"));
    assert_eq!(code, 0, "{stop} {err}");
    assert_eq!(stop["acknowledged"].as_array().unwrap().len(), 2, "{stop}");
    assert_eq!(stop["command"]["by"], "operator");
    std::thread::sleep(Duration::from_millis(500));
    // The `operator` certificate is not enough to resume: the token is
    // needed too.
    refused_resume(scenario, &router, &secure("operator"), false);
    let wrong = [&secure("operator")[..], &["--token", WRONG_TOKEN]].concat();
    refused_resume(scenario, &router, &wrong, true);
    let token = token_file(&out);
    let good = [&secure("operator")[..], &["--token-file", &token]].concat();
    let (code, resume, err) = run_command("resume", scenario, &router, &good);
    assert_eq!(code, 0, "{resume} {err}");
    let up = up_summary(up, &out);
    for r in up["robots"].as_array().unwrap() {
        let c = &r["commands"];
        assert_eq!((f(c, &["stops"]), f(c, &["resumes"])), (1.0, 1.0), "{r}");
        assert_eq!(f(c, &["unauthorized"]), 1.0, "{r}");
    }
}
