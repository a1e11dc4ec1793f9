//! `echelon fleet doctor`: before a run, what would go wrong, per robot and
//! for the hub, without moving anything (it sends no `cmd_vel`, puts no
//! fleet key: it listens, reads liveliness tokens and asks probes).
//!
//! - **hub**: reached at its endpoint ([`DoctorOptions::hub`]), its router's
//!   probe ([`crate::probe`]): its version, its clock against this
//!   machine's (only warns), the round trips.
//! - **robot K**, its ROS 2 side (`doctor/ros.rs`): its robot's router reached at
//!   the agent's `ros2.connect` (or the hub, when it has none); odometry on
//!   the scenario's topic at the scenario's `odom_rate` (fails below
//!   [`ODOM_FAIL_BELOW`] of it, warns below [`ODOM_WARN_BELOW`] and above
//!   [`ODOM_WARN_ABOVE`]), or heard under another namespace; a `cmd_vel`
//!   reader (and its hazard and e-stop publishers) in its graph; its fixes'
//!   rate and age.
//! - **robot K**, its process's probe, when it runs (an on-board robot's
//!   joins the hub before the run; a hub-placed one is started by `fleet
//!   up`, so its absence is only said): its version, its clock minus the
//!   hub's (warns above [`CLOCK_WARN`], fails above [`CLOCK_FAIL`]), the
//!   round trips (p99 against the scenario's `link_timeout`: warn above
//!   [`RTT_WARN`] of it or at any loss, fail above [`RTT_FAIL`] of it or
//!   more than [`LOSS_FAIL`] lost).
//! - in secure mode, every certificate of the directory: signed by its CA,
//!   named for its identity, valid now and for more than
//!   [`EXPIRY_WARNING_DAYS`] days.
//!
//! Every wait is bounded ([`DoctorOptions::timeout`],
//! [`DoctorOptions::listen_for`]); the robots are checked at once, each on
//! its own thread.

use std::time::{Duration, Instant};

use zenoh::{Session, Wait};

use echelon::scenario::{Overrides, Scenario};

use crate::FleetError;
use crate::keys::Keys;
use crate::net::{self, NetOptions, Secure};
use crate::probe::{self, ProbeStats};
use probes::{hub_rows, process_rows};

mod certs;
mod probes;
mod report;
mod ros;

pub use certs::EXPIRY_WARNING_DAYS;
pub use report::{Counts, DoctorReport, Row, Status};
pub use ros::{ODOM_FAIL_BELOW, ODOM_WARN_ABOVE, ODOM_WARN_BELOW};

/// A clock further than this from the hub's warns, s.
pub const CLOCK_WARN: f64 = 0.005;
/// A clock further than this from the hub's fails, s: stamps, latencies
/// and fixes are off by as much.
pub const CLOCK_FAIL: f64 = 0.05;
/// Round trips slower (p99) than this share of the scenario's
/// `[fleet] link_timeout` warn (50 ms of the default 0.2 s).
pub const RTT_WARN: f64 = 0.25;
/// Round trips slower (p99) than this share of `link_timeout` fail: the
/// way there alone takes half the time after which a link is stale.
pub const RTT_FAIL: f64 = 1.0;
/// More than this share of probes lost fails (any loss warns).
pub const LOSS_FAIL: f64 = 0.1;
/// How often a probe is asked.
pub const PROBE_INTERVAL: Duration = Duration::from_millis(100);

/// What `fleet doctor` checks, and how long it may take.
#[derive(Debug, Clone)]
pub struct DoctorOptions {
    /// The scenario the fleet will run.
    pub scenario: Scenario,
    /// The fleet name (absent: the scenario's).
    pub fleet: Option<String>,
    /// How the hub is reached (a client of its router); `None`: not given,
    /// the hub and the robots' processes are not checked.
    pub hub: Option<NetOptions>,
    /// Secure mode: the certificates checked, and the identity the robots'
    /// routers are reached with.
    pub secure: Option<Secure>,
    /// How long each robot's odometry and fixes are listened to, and each
    /// process probed.
    pub listen_for: Duration,
    /// Longest wait to reach an endpoint, or for a probe's answer.
    pub timeout: Duration,
}

/// Opens a session with `net`, waiting at most `timeout` for its `connect`
/// endpoints.
fn open_within(net: &NetOptions, timeout: Duration) -> Result<Session, FleetError> {
    net::open_within(net, timeout).map_err(|e| {
        FleetError::Config(match e {
            FleetError::TimedOut(_) => "nothing answered".to_owned(),
            FleetError::Zenoh(why) => one_line(why.trim_start_matches("opening the session: ")),
            other => one_line(&other.to_string()),
        })
    })
}

/// Zenoh's refusal to open, in one short line: "nothing answered" when
/// no endpoint did, else its first line without the source location
/// Zenoh appends, at most 200 characters.
fn one_line(text: &str) -> String {
    if text.starts_with("Unable to connect to any of") {
        return "nothing answered".to_owned();
    }
    let line = text.lines().next().unwrap_or_default();
    let line = line.split(" at /").next().unwrap_or_default();
    match line.char_indices().nth(200) {
        Some((i, _)) => format!("{}…", &line[..i]),
        None => line.to_owned(),
    }
}

/// `tcp/10.0.0.1:7447` → `tcp`.
fn transport(endpoints: &[String]) -> String {
    let mut t: Vec<&str> = endpoints
        .iter()
        .filter_map(|e| e.split('/').next())
        .collect();
    t.dedup();
    t.join(", ")
}

/// `s` seconds in milliseconds, one decimal.
fn ms(s: f64) -> String {
    format!("{:.1} ms", s * 1e3)
}

/// The session to the hub (`--hub`), with the row saying whether it was
/// reached (and how), pushed on `rows`; none when not given or not reached.
fn open_hub(opts: &DoctorOptions, rows: &mut Vec<Row>) -> Option<Session> {
    let Some(net) = &opts.hub else {
        rows.push(Row::new(
            "hub",
            "reachable",
            Status::Info,
            "not given",
            "give --hub ENDPOINT to check the hub and the robots' processes",
        ));
        return None;
    };
    let endpoints = net.connect.join(" or ");
    let started = Instant::now();
    match open_within(net, opts.timeout) {
        Ok(s) => {
            rows.push(Row::new(
                "hub",
                "reachable",
                Status::Pass,
                &endpoints,
                format!(
                    "transport {}, linked in {}",
                    transport(&net.connect),
                    ms(started.elapsed().as_secs_f64())
                ),
            ));
            Some(s)
        }
        Err(e) => {
            rows.push(Row::new(
                "hub",
                "reachable",
                Status::Fail,
                &endpoints,
                format!(
                    "not reached within {:.1} s: {e} (is the hub's router running there, the port open, the transport right?)",
                    opts.timeout.as_secs_f64()
                ),
            ));
            None
        }
    }
}

/// Runs every check; fails only on a scenario that cannot be built (what
/// the network says is in the rows).
pub fn run(opts: &DoctorOptions) -> Result<DoctorReport, FleetError> {
    let settings = opts.scenario.fleet()?;
    let plan = opts.scenario.build(&Overrides::default())?.plan;
    let keys = Keys::new(opts.fleet.as_deref().unwrap_or(&settings.name));
    let agents = plan.agents().len() as u32;
    let mut rows = Vec::new();
    let hub = open_hub(opts, &mut rows);
    let rounds = (opts.listen_for.as_secs_f64() / PROBE_INTERVAL.as_secs_f64()).ceil() as u32;
    let rounds = rounds.max(1);
    let ask = |name: &str| {
        hub.as_ref()
            .map(|s| probe::ask(s, &keys, name, rounds, PROBE_INTERVAL, opts.timeout))
    };
    let (hub_probe, found) = std::thread::scope(|scope| {
        let hub_probe = scope.spawn(|| ask("router"));
        let threads: Vec<_> = (1..=agents)
            .map(|k| {
                let (settings, plan, hub, ask) = (&settings, &plan, hub.as_ref(), &ask);
                scope.spawn(move || check_agent(k, settings, plan, hub, opts, ask))
            })
            .collect();
        let found: Vec<_> = (1..=agents)
            .zip(threads)
            .map(|(k, t)| {
                t.join().unwrap_or_else(|_| {
                    let why = "its checks stopped unexpectedly";
                    let row = Row::new(&format!("robot-{k}"), "doctor", Status::Fail, "", why);
                    (vec![row], None)
                })
            })
            .collect();
        (hub_probe.join().ok().flatten(), found)
    });
    let hub_probe = match hub_probe {
        Some(Err(e)) => {
            rows.push(asking_failed("hub", "router probe", &e));
            None
        }
        p => p.and_then(Result::ok),
    };
    if hub.is_some() {
        rows.extend(hub_rows(
            hub_probe.as_ref(),
            &keys,
            opts.timeout,
            settings.link_timeout,
        ));
    }
    let hub_offset = hub_probe.as_ref().and_then(|p| p.offset);
    let hub_rtt = hub_probe.as_ref().and_then(|p| p.rtt_p50).unwrap_or(0.0);
    for (k, (ros_rows, stats)) in (1..=agents).zip(found) {
        let subject = format!("robot-{k}");
        rows.extend(ros_rows);
        let placement = settings
            .placement
            .get(k as usize - 1)
            .copied()
            .unwrap_or_default();
        let stats = match stats {
            Some(Err(e)) => {
                rows.push(asking_failed(&subject, "robot process", &e));
                continue;
            }
            s => s.and_then(Result::ok),
        };
        rows.extend(process_rows(
            &subject,
            stats.as_ref(),
            hub.is_some(),
            placement,
            hub_offset.map(|o| (o, hub_rtt)),
            settings.link_timeout,
        ));
    }
    if let Some(secure) = &opts.secure {
        let now = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_secs() as i64);
        rows.extend(certs::check(&secure.dir, &net::identities(agents), now));
    }
    // Hub first, then robot by robot, each subject's rows in order.
    rows.sort_by_key(|r| {
        r.subject
            .strip_prefix("robot-")
            .and_then(|k| k.parse::<u32>().ok())
            .unwrap_or(0)
    });
    if let Some(s) = hub {
        let _ = s.close().wait();
    }
    Ok(DoctorReport::new(keys.fleet(), rows))
}

type Asked = Option<Result<ProbeStats, FleetError>>;

/// The failed row of a probe that could not be asked.
fn asking_failed(subject: &str, check: &str, e: &FleetError) -> Row {
    Row::new(subject, check, Status::Fail, "not asked", e.to_string())
}

/// Robot `k`'s ROS 2 rows, and its process's probe (`None`: no hub to
/// ask it through).
fn check_agent(
    k: u32,
    settings: &echelon::scenario::FleetSettings,
    plan: &echelon::plan::Plan,
    hub: Option<&Session>,
    opts: &DoctorOptions,
    ask: &(dyn Fn(&str) -> Asked + Sync),
) -> (Vec<Row>, Asked) {
    let subject = format!("robot-{k}");
    let name = crate::role::Member::Robot(k).liveliness();
    let Some(link) = settings.ros2.get(k as usize - 1) else {
        return (Vec::new(), ask(&name));
    };
    let velocity = crate::robot::agent_spec(plan, k).is_ok_and(|s| s.velocity_robot().is_some());
    if !velocity {
        let row = Row::new(
            &subject,
            "ros 2 base",
            Status::Info,
            "none",
            "a torque-driven agent runs on a simulated plant: nothing of ROS 2 to check",
        );
        return (vec![row], ask(&name));
    }
    // Its process is probed while its robot is reached and listened to.
    std::thread::scope(|scope| {
        let probing = scope.spawn(|| ask(&name));
        ros_checks(k, &subject, link, plan, hub, opts, probing)
    })
}

/// Robot `k`'s ROS 2 rows (its robot reached, listened to for
/// `listen_for`), with its process's probe `probing` joined.
fn ros_checks(
    k: u32,
    subject: &str,
    link: &echelon::scenario::Ros2Link,
    plan: &echelon::plan::Plan,
    hub: Option<&Session>,
    opts: &DoctorOptions,
    probing: std::thread::ScopedJoinHandle<'_, Asked>,
) -> (Vec<Row>, Asked) {
    let mut rows = Vec::new();
    let mut own = None;
    let session = if link.connect.is_empty() {
        match hub {
            Some(h) => {
                rows.push(Row::new(
                    subject,
                    "ros 2 reachable",
                    Status::Pass,
                    "through the hub",
                    "no ros2.connect: its topics are on the fleet's network",
                ));
                Some(h)
            }
            None => {
                rows.push(Row::new(
                    subject,
                    "ros 2 reachable",
                    Status::Fail,
                    "not checked",
                    "no ros2.connect: its topics are on the fleet's network; give --hub ENDPOINT",
                ));
                None
            }
        }
    } else {
        let endpoints = link.connect.join(" or ");
        let fleet = NetOptions {
            secure: opts.secure.clone(),
            ..NetOptions::default()
        };
        let started = Instant::now();
        let opened = net::robot_router(k, &link.connect, &fleet)
            .and_then(|net| open_within(&net, opts.timeout));
        match opened {
            Ok(s) => {
                rows.push(Row::new(
                    subject,
                    "ros 2 reachable",
                    Status::Pass,
                    &endpoints,
                    format!(
                        "its robot's router (ros2.connect), transport {}, linked in {}",
                        transport(&link.connect),
                        ms(started.elapsed().as_secs_f64())
                    ),
                ));
                own = Some(s);
                own.as_ref()
            }
            Err(e) => {
                rows.push(Row::new(
                    subject,
                    "ros 2 reachable",
                    Status::Fail,
                    &endpoints,
                    format!(
                        "its robot's router (ros2.connect) not reached within {:.1} s: {e} (is rmw_zenohd or the bridge running on the robot, the address and port right, a firewall?)",
                        opts.timeout.as_secs_f64()
                    ),
                ));
                None
            }
        }
    };
    let watch = session.map(|s| ros::Watch::start(s, link, fix_timing(plan, k, link)));
    let asked = probing.join().ok().flatten();
    match watch {
        Some(Ok(watch)) => {
            if let Some(rest) = opts.listen_for.checked_sub(watch.started().elapsed()) {
                std::thread::sleep(rest);
            }
            rows.extend(watch.rows(subject));
        }
        Some(Err(e)) => rows.push(Row::new(
            subject,
            "ros 2 graph",
            Status::Fail,
            "unread",
            e.to_string(),
        )),
        None => {}
    }
    if let Some(s) = own {
        let _ = s.close().wait();
    }
    (rows, asked)
}

/// Agent `k`'s fixes: their period and the timeout after which they are
/// missed, s, when it takes fixes.
fn fix_timing(
    plan: &echelon::plan::Plan,
    k: u32,
    link: &echelon::scenario::Ros2Link,
) -> Option<(f64, f64)> {
    let source = link.fixes.as_ref()?;
    let odometry = plan.odometer(k as usize - 1)?.spec();
    let period = odometry.fixes()?.interval(odometry.period());
    Some((period, source.timeout.unwrap_or(3.0 * period)))
}
