//! What the CLI's process tests share: the binary, and a child process
//! that is killed if the test ends first.

#![allow(dead_code, clippy::unwrap_used)]

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::time::{Duration, Instant};

use serde_json::Value;

/// The `echelon` binary under test.
pub(crate) const EXE: &str = env!("CARGO_BIN_EXE_echelon");

/// `K` of a topic `PREFIX K SUFFIX` (`/agent/2/state`, `/robot2/odom`),
/// if `topic` is one.
pub(crate) fn topic_number(topic: &str, prefix: &str, suffix: &str) -> Option<u32> {
    topic
        .strip_prefix(prefix)?
        .strip_suffix(suffix)?
        .parse()
        .ok()
}

/// Asserts that the process `what` succeeded, with its stderr and stdout
/// otherwise.
pub(crate) fn check(out: &Output, what: &str) {
    assert!(
        out.status.success(),
        "{what} failed: {}\nstdout: {}",
        String::from_utf8_lossy(&out.stderr),
        String::from_utf8_lossy(&out.stdout)
    );
}

/// Runs `echelon ARGS… LAST` to its end and checks that it succeeded.
pub(crate) fn echelon_ok(args: &[&str], last: &Path) {
    let out = Command::new(EXE).args(args).arg(last).output().unwrap();
    check(&out, &args.join(" "));
}

/// A `fleet up` output directory's `fleet-summary.json`.
pub(crate) fn fleet_summary(dir: &Path) -> Value {
    serde_json::from_str(&std::fs::read_to_string(dir.join("fleet-summary.json")).unwrap()).unwrap()
}

/// Runs `echelon fleet up ARGS… --out DIR` to its end and checks that it
/// succeeded; its `fleet-summary.json`.
pub(crate) fn fleet_up(args: &[&str], dir: &Path) -> Value {
    echelon_ok(&[&["fleet", "up"], args, &["--out"]].concat(), dir);
    fleet_summary(dir)
}

/// Starts `echelon fleet up ARGS… --out DIR` on a thread, for a test that
/// talks to the fleet meanwhile; the thread gives its output.
pub(crate) fn fleet_up_in_background(args: &[&str], dir: &Path) -> std::thread::JoinHandle<Output> {
    let args: Vec<String> = args.iter().map(|a| (*a).to_owned()).collect();
    let dir = dir.to_owned();
    std::thread::spawn(move || {
        Command::new(EXE)
            .args(["fleet", "up"])
            .args(&args)
            .arg("--out")
            .arg(&dir)
            .output()
            .unwrap()
    })
}

/// A secure fleet: certificates for `robots` robots made in `dir/certs`
/// ([`certs`]), and `echelon fleet up ARGS… --secure DIR/certs` started into
/// `dir/fleet` on a thread ([`fleet_up_in_background`]); the certificates'
/// and the fleet's directories and the thread.
pub(crate) fn secure_fleet_up_in_background(
    dir: &Path,
    robots: u32,
    args: &[&str],
) -> (PathBuf, PathBuf, std::thread::JoinHandle<Output>) {
    let certs = certs(dir, robots);
    let fleet_dir = dir.join("fleet");
    let secure = ["--secure", certs.to_str().unwrap()];
    let fleet = fleet_up_in_background(&[args, &secure].concat(), &fleet_dir);
    (certs, fleet_dir, fleet)
}

/// The number at `path` in a JSON report.
pub(crate) fn f(v: &Value, path: &[&str]) -> f64 {
    path.iter()
        .fold(v, |v, k| &v[*k])
        .as_f64()
        .unwrap_or_else(|| panic!("{path:?} in {v}"))
}

/// Holds the one fleet slot of the machine's test run: a test that runs
/// fleet processes takes it first, so fleets run one at a time, whichever
/// test binary or process they are in (`cargo test` runs one binary at a
/// time, but a runner with a process per test, such as cargo-nextest, or two
/// `cargo test` at once would not). Each fleet is a
/// handful of real-time processes at ×10 whose convergence, latency and
/// sample counts depend on getting the CPU when their ticks come; two fleets
/// at once on a 2-core machine starve each other. The slot is an exclusive
/// lock on a file in the target directory (`flock`), released when the
/// returned file is dropped, also when the test panics or its process dies.
pub(crate) fn one_fleet_at_a_time() -> std::fs::File {
    let path = std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join("one-fleet-at-a-time.lock");
    let file = std::fs::OpenOptions::new()
        .create(true)
        .truncate(false)
        .write(true)
        .open(&path)
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    file.lock()
        .unwrap_or_else(|e| panic!("locking {}: {e}", path.display()));
    file
}

/// Kills the child if the test ends first.
pub(crate) struct Guard(pub(crate) Child);

impl Drop for Guard {
    fn drop(&mut self) {
        if matches!(self.0.try_wait(), Ok(None)) {
            let _ = self.0.kill();
            let _ = self.0.wait();
        }
    }
}

impl Guard {
    /// Sends SIGTERM.
    pub(crate) fn terminate(&self) {
        let _ = Command::new("kill")
            .args(["-TERM", &self.0.id().to_string()])
            .status();
    }

    /// Waits for the process to exit; its last JSON line.
    pub(crate) fn report(mut self) -> Value {
        let status = self.0.wait().unwrap();
        let mut out = String::new();
        let mut err = String::new();
        std::io::Read::read_to_string(&mut self.0.stdout.take().unwrap(), &mut out).unwrap();
        std::io::Read::read_to_string(&mut self.0.stderr.take().unwrap(), &mut err).unwrap();
        assert!(status.success(), "{status}: {err}");
        let line = out
            .lines()
            .rfind(|l| l.starts_with('{'))
            .unwrap_or_else(|| panic!("no report: {out} {err}"));
        serde_json::from_str(line).unwrap()
    }
}

/// Starts `echelon ARGS` with piped output.
pub(crate) fn spawn(args: &[&str]) -> Guard {
    Guard(
        Command::new(EXE)
            .args(args)
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap(),
    )
}

/// `n` free loopback TCP endpoints.
pub(crate) fn ports(n: usize) -> Vec<String> {
    let l: Vec<_> = (0..n)
        .map(|_| std::net::TcpListener::bind("127.0.0.1:0").unwrap())
        .collect();
    l.iter()
        .map(|l| format!("tcp/127.0.0.1:{}", l.local_addr().unwrap().port()))
        .collect()
}

/// The test's own Zenoh session as process 0 of a full mesh of peers on
/// the endpoints `e` (see [`spawn_peer`]): it listens on `e[0]`.
pub(crate) fn open_peer(e: &[String]) -> zenoh::Session {
    echelon_fleet::net::open(&echelon_fleet::net::NetOptions {
        listen: vec![e[0].clone()],
        ..Default::default()
    })
    .unwrap()
}

/// Starts `echelon CMD…` as process `i` of a full mesh of peers on the
/// endpoints `e`: `--listen e[i]`, and `--connect` each of `e[..i]`.
pub(crate) fn spawn_peer(cmd: &[&str], e: &[String], i: usize) -> Guard {
    let mut a = cmd.to_vec();
    a.extend(["--listen", &e[i]]);
    for before in &e[..i] {
        a.extend(["--connect", before]);
    }
    spawn(&a)
}

/// The built-in scenario `builtin` with `agents[k]` put first in its agent
/// `k`'s table (one entry per agent at most) and `extra` appended, written
/// to `dir/NAME.toml`; that path.
pub(crate) fn scenario_variant(
    dir: &Path,
    builtin: &str,
    name: &str,
    agents: &[&str],
    extra: &str,
) -> String {
    let src = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join(format!("../../scenarios/{builtin}.toml")),
    )
    .unwrap();
    let mut parts = src.split("[[agents]]\n");
    let mut out = parts.next().unwrap().to_owned();
    let mut n = 0;
    for part in parts {
        out.push_str("[[agents]]\n");
        out.push_str(agents.get(n).copied().unwrap_or_default());
        out.push_str(part);
        n += 1;
    }
    assert!(agents.len() <= n, "{builtin} has {n} agents");
    out.push_str(extra);
    let path = dir.join(format!("{name}.toml"));
    std::fs::write(&path, out).unwrap();
    path.to_string_lossy().into_owned()
}

/// `echelon fleet certs --robots ROBOTS` into `dir/certs`; that directory.
pub(crate) fn certs(dir: &Path, robots: u32) -> PathBuf {
    let certs = dir.join("certs");
    echelon_ok(&["fleet", "certs", "--robots", &robots.to_string()], &certs);
    certs
}

/// The endpoint of each process of a `fleet up` writing to `dir` (its
/// `endpoints.json`, waited for), without the topology.
pub(crate) fn endpoints_of(dir: &Path) -> BTreeMap<String, String> {
    let path = dir.join("endpoints.json");
    let started = Instant::now();
    while !path.exists() {
        assert!(
            started.elapsed() < Duration::from_secs(60),
            "no endpoints.json"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    std::thread::sleep(Duration::from_millis(100));
    let mut all: BTreeMap<String, String> =
        serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
    assert!(all.remove("topology").is_some(), "{all:?}");
    all
}

/// Zenoh's mutual-TLS settings for a process holding `identity`'s
/// certificate from `certs` (a stolen one, in the rogue tests).
pub(crate) fn tls_as(certs: &Path, identity: &str) -> Value {
    let path = |name: String| certs.join(name).display().to_string();
    serde_json::json!({
        "root_ca_certificate": path("ca.pem".into()),
        "listen_certificate": path(format!("{identity}.pem")),
        "listen_private_key": path(format!("{identity}-key.pem")),
        "connect_certificate": path(format!("{identity}.pem")),
        "connect_private_key": path(format!("{identity}-key.pem")),
        "enable_mtls": true,
    })
}

/// The Zenoh configuration of a peer outside the fleet that connects to
/// `connect` over QUIC with the TLS settings `tls`, waiting `timeout_ms` for
/// them (and exiting if they do not answer, with `exit_on_failure`).
pub(crate) fn outsider_config(
    connect: &[String],
    tls: Value,
    timeout_ms: u64,
    exit_on_failure: bool,
) -> Value {
    serde_json::json!({
        "mode": "peer",
        "scouting": {"multicast": {"enabled": false}},
        "listen": {"endpoints": ["quic/127.0.0.1:0"]},
        "connect": {"endpoints": connect, "timeout_ms": timeout_ms, "exit_on_failure": exit_on_failure},
        "transport": {"link": {"tls": tls}},
    })
}
