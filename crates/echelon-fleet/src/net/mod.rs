//! Zenoh sessions: the default configuration (peer mode, no multicast
//! scouting, explicit endpoints), client mode (one link to a router), router
//! mode (`fleet router`), a user's `--zenoh-config` file, and the secure mode
//! (mutual TLS with access control by certificate common name). Every
//! process's session, the router's included, is configured here; the
//! secure mode's access control is generated in `net/acl.rs`.

use std::path::PathBuf;

use serde::Serialize;
use serde_json::json;
use zenoh::bytes::ZBytes;
use zenoh::{Config, Session, Wait};

use crate::FleetError;

mod acl;
pub use acl::{
    RosAcl, Secure, access_control, answers, common_name, identities, identity_files, probe_key,
    publishes, ros_acl, subscribes,
};

/// The environment variable Zenoh sizes its runtime from (read once, when
/// a process first uses Zenoh; RON syntax, zenoh-runtime's `ZRuntime`).
pub const ZENOH_RUNTIME_ENV: &str = "ZENOH_RUNTIME";

/// Zenoh's runtime for a fleet process that sends a few samples per tick
/// (a robot, a base, the leader, the collector): its five runtimes
/// (application, acceptor, transmission, reception, network; by default
/// 1 + 1 + 1 + 2 + 1 worker threads, each with its own timer and I/O
/// driver) handed over to one runtime of one worker thread. A sample then
/// goes out or comes in with one thread woken, not a chain of them.
pub const CLIENT_RUNTIME: &str = "(app: (worker_threads: 1), acc: (handover: app), tx: (handover: app), rx: (handover: app), net: (handover: app))";

/// Zenoh's runtime for a router: the same single runtime, with two worker
/// threads (it forwards every sample of the fleet).
pub const ROUTER_RUNTIME: &str = "(app: (worker_threads: 2), acc: (handover: app), tx: (handover: app), rx: (handover: app), net: (handover: app))";

/// The `ZENOH_RUNTIME` a fleet process of role `role` is started with
/// ([`ROUTER_RUNTIME`] for `router…`, else [`CLIENT_RUNTIME`]), unless
/// this process's environment sets one already (`None`: theirs is
/// inherited, overriding ours).
pub fn zenoh_runtime(role: &str) -> Option<&'static str> {
    if std::env::var_os(ZENOH_RUNTIME_ENV).is_some() {
        return None;
    }
    Some(if role.starts_with("router") {
        ROUTER_RUNTIME
    } else {
        CLIENT_RUNTIME
    })
}

/// Makes this process run with [`zenoh_runtime`]`(role)`: if the
/// environment sets no `ZENOH_RUNTIME`, re-executes the process (same
/// binary, arguments and process id) with it set; returns at once when it
/// is set already (by the user, or by `fleet up` for its children). Call
/// before anything uses Zenoh. If the re-execution fails it says so and
/// returns (Zenoh's default runtime then).
pub fn exec_with_sized_runtime(role: &str) {
    #[cfg(unix)]
    {
        use std::os::unix::process::CommandExt;
        let Some(runtime) = zenoh_runtime(role) else {
            return;
        };
        let Ok(exe) = std::env::current_exe() else {
            return;
        };
        let err = std::process::Command::new(exe)
            .args(std::env::args_os().skip(1))
            .env(ZENOH_RUNTIME_ENV, runtime)
            .exec();
        eprintln!(
            "could not restart with {ZENOH_RUNTIME_ENV} set ({err}): Zenoh's default runtime"
        );
    }
    #[cfg(not(unix))]
    let _ = role;
}

/// How long `open` waits for every `connect` endpoint, s of real time.
pub const CONNECT_TIMEOUT_MS: u64 = 30_000;

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

/// Whether `e` is a `tcp/` or `udp/` endpoint on this machine's loopback
/// (`127.0.0.0/8`, `[::1]`, `localhost`): traffic that never leaves it.
pub fn is_loopback_endpoint(e: &str) -> bool {
    let Some((proto, address)) = echelon::scenario::endpoint_address(e) else {
        return false;
    };
    let host = echelon::scenario::endpoint_host_port(address).map_or(address, |(h, _)| h);
    matches!(proto, "tcp" | "udp")
        && (host == "localhost"
            || host == "[::1]"
            || host
                .parse::<std::net::Ipv4Addr>()
                .is_ok_and(|ip| ip.is_loopback()))
}

/// The session options of agent `agent`'s robot's own router: a client of
/// the first of `connect` that answers (one link; no gossip, so no
/// link to the robot's own nodes), in secure mode with the process's
/// identity (the robot's router must then be a `tls/` or `quic/` listener
/// trusting the fleet's CA: docs/real-robots.md) — unless every endpoint
/// is on this machine's loopback (an on-board robot process next to its
/// robot's router, docs/lab.md): plain TCP there, nothing leaves the
/// machine.
pub fn robot_router(
    agent: u32,
    connect: &[String],
    fleet: &NetOptions,
) -> Result<NetOptions, FleetError> {
    if !connect.is_empty() && connect.iter().all(|e| is_loopback_endpoint(e)) {
        return Ok(NetOptions {
            mode: Some(Mode::Client),
            listen: Vec::new(),
            connect: connect.to_vec(),
            zenoh_config: None,
            secure: None,
        });
    }
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
    let [ca, cert, key] = secure_files(&s.dir, &s.identity)?;
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

/// The files `identity` needs in the secure mode, `[ca, certificate, key]`,
/// or which one is missing from `dir`.
pub fn secure_files(dir: &std::path::Path, identity: &str) -> Result<[PathBuf; 3], FleetError> {
    let ca = dir.join("ca.pem");
    let (cert, key) = identity_files(dir, identity);
    for f in [&ca, &cert, &key] {
        if !f.is_file() {
            return Err(FleetError::Config(format!(
                "secure mode needs {} (make the certificates with `echelon fleet certs {}`)",
                f.display(),
                dir.display()
            )));
        }
    }
    Ok([ca, cert, key])
}

/// Opens a session (blocks until every `connect` endpoint is reached, or fails).
pub fn open(opts: &NetOptions) -> Result<Session, FleetError> {
    open_config(config(opts)?, opts)
}

/// [`open`], waiting at most `timeout` for its `connect` endpoints (a
/// check, a status: bounded by what the operator asked, not the fleet's
/// connection timeout).
pub fn open_within(opts: &NetOptions, timeout: std::time::Duration) -> Result<Session, FleetError> {
    let mut config = config(opts)?;
    set(
        &mut config,
        "connect/timeout_ms",
        json!(timeout.as_millis().max(1) as u64),
    )?;
    open_config(config, opts)
}

/// Opens a session of `config` (made from `opts`): nothing answering at
/// its endpoints is [`FleetError::TimedOut`], in one line.
fn open_config(config: Config, opts: &NetOptions) -> Result<Session, FleetError> {
    zenoh::open(config).wait().map_err(|e| {
        // Nothing answered at the endpoints it must reach (a client's
        // router, a hub): a timeout, said in one line.
        if e.to_string().starts_with("Unable to connect to any of") {
            FleetError::TimedOut(format!(
                "no answer from {}: nothing listens there or it cannot be reached (is the hub's `fleet up --hub` or the router running? a firewall?)",
                opts.connect.join(" or ")
            ))
        } else {
            FleetError::Zenoh(format!("opening the session: {e}"))
        }
    })
}

/// Publishes `payload` on `publisher`: without an attachment stamped with
/// the session's timestamp (the receivers' latency measure,
/// [`crate::latency`]), with one unstamped (as rmw_zenoh does).
pub(crate) fn send(
    session: &Session,
    publisher: &zenoh::pubsub::Publisher<'_>,
    payload: &[u8],
    attachment: Option<&[u8]>,
) -> Result<(), FleetError> {
    let put = publisher.put(payload.to_vec());
    let put = match attachment {
        None => put.timestamp(session.new_timestamp()),
        Some(attachment) => put.attachment(attachment.to_vec()),
    };
    put.wait()
        .map_err(|e| FleetError::Zenoh(format!("publishing: {e}")))
}

/// Puts `payload` on `key` (a non-declared publication, e.g. a robot's
/// stats), stamped like [`send`] without an attachment; errors are ignored
/// (best effort).
pub(crate) fn put_stamped(session: &Session, key: &str, payload: impl Into<ZBytes>) {
    let _ = session
        .put(key, payload)
        .timestamp(session.new_timestamp())
        .wait();
}

/// The longest [`flush`] waits, real time.
pub(crate) const FLUSH_TIMEOUT: std::time::Duration = std::time::Duration::from_secs(2);

/// Returns once the router `session` is a client of holds everything it
/// published before (or after `timeout`, with an error): a round trip
/// behind its last words, before the session closes.
///
/// Closing does not wait for them: over QUIC (the secure mode's links)
/// Zenoh closes the connection at once (quinn's `Connection::close`, with
/// no linger), abandoning stream data the router has not received yet; over
/// TCP the socket lingers. The round trip is a query on `key` (one the
/// access control lets the process declare on: its own token or
/// subscription). A query goes at the data priority, the priority of every
/// put, so on the same link and stream, behind them (a liveliness query
/// would not: Zenoh sends its interest at the control priority, on a QUIC
/// stream of its own); a client sends it to its router whatever matches
/// it, and the router, which routes what arrives on a link in order,
/// answers (its final reply, or the queryables' answers it forwards) once
/// it came: everything before it is routed by then, queued on the live
/// links to its subscribers. In a peer mesh a query reaches only the peers
/// with a matching queryable, so there it proves nothing (a mesh over TCP
/// relies on the socket's linger).
pub(crate) fn flush(
    session: &Session,
    key: &str,
    timeout: std::time::Duration,
) -> Result<(), FleetError> {
    let replies = session
        .get(key)
        .timeout(timeout)
        .wait()
        .map_err(|e| FleetError::Zenoh(format!("flushing (query on {key}): {e}")))?;
    let mut answered = true;
    // Ends when the query is final: answered, or timed out.
    while let Ok(reply) = replies.recv() {
        answered &= reply.result().is_ok();
    }
    match answered {
        true => Ok(()),
        false => Err(FleetError::Zenoh(format!(
            "no answer to the flush query on {key} within {:.0} s",
            timeout.as_secs_f64()
        ))),
    }
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
mod tests;
