//! The probe every robot process and every router answers, for `fleet
//! doctor`: who it is (its member, echelon version, host, process id, Zenoh
//! id) and its wall clock, read when the query arrives.
//!
//! A process [declares](declare) a queryable on `echelon/<fleet>/probe/<name>`
//! ([`Keys::probe`], `<name>` its liveliness name: `robot/3`; a router,
//! which carries every fleet, on `echelon/*/probe/router`). [`ask`] sends
//! `rounds` queries, one every `interval`, and estimates as NTP does, per
//! round, from the wall time `t_send` the query left, the time `t_remote`
//! the answer was made at and the round trip `rtt` (a monotonic clock):
//!
//! ```text
//! offset = t_remote − (t_send + rtt / 2)
//! ```
//!
//! the answerer's wall clock minus the asker's. A round's estimate is off by
//! half the difference of its two legs' delays, so by less than `rtt / 2`
//! (property-tested below); the stats take the median over the answered
//! rounds, and the round trips' p50 and p99 and the share of rounds lost.
//! The answerer's clock is its process's wall clock: a robot started with
//! `--wall-clock-jump` answers with its stepped clock.

use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use serde::{Deserialize, Serialize};
use zenoh::Wait;

use crate::FleetError;
use crate::keys::Keys;
use crate::role::Member;

/// What a process answers to a probe, JSON.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct ProbeAnswer {
    /// Its liveliness name (`robot/3`, `router`).
    pub member: String,
    /// Its echelon version (`CARGO_PKG_VERSION` of echelon-fleet).
    pub version: String,
    /// Its host name.
    pub host: String,
    /// Its process id.
    pub pid: u32,
    /// Its Zenoh session id.
    pub zid: String,
    /// The address it reaches the fleet from (its side of the route to
    /// the first endpoint it connects to), when it connects to one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub address: Option<String>,
    /// Its wall clock when it answered, ns since the UNIX epoch.
    pub unix_ns: u64,
}

/// This build's echelon version, as every probe answer carries it.
pub const VERSION: &str = env!("CARGO_PKG_VERSION");

/// This machine's host name (`unknown` when the system does not say).
pub fn host_name() -> String {
    let name = rustix::system::uname();
    let name = name.nodename().to_string_lossy();
    match name.trim() {
        "" => "unknown".to_owned(),
        n => n.to_owned(),
    }
}

/// Declares `member`'s probe on `session` in the fleet of `keys` (a
/// router: [`Keys::any`]); it answers while the returned queryable lives.
pub fn declare(
    session: &zenoh::Session,
    keys: &Keys,
    member: Member,
) -> Result<zenoh::query::Queryable<()>, FleetError> {
    declare_from(session, keys, member, None)
}

/// [`declare`], the answers naming `address` as where the process reaches
/// the fleet from ([`local_address_towards`]).
pub fn declare_from(
    session: &zenoh::Session,
    keys: &Keys,
    member: Member,
    address: Option<String>,
) -> Result<zenoh::query::Queryable<()>, FleetError> {
    let key = keys.probe(&member.liveliness());
    let (name, host, zid) = (member.liveliness(), host_name(), session.zid().to_string());
    let pid = std::process::id();
    session
        .declare_queryable(&key)
        .callback(move |q| {
            let answer = ProbeAnswer {
                member: name.clone(),
                version: VERSION.to_owned(),
                host: host.clone(),
                pid,
                zid: zid.clone(),
                address: address.clone(),
                unix_ns: crate::unix_nanos(),
            };
            if let Ok(json) = serde_json::to_vec(&answer) {
                let _ = q.reply(q.key_expr().clone(), json).wait();
            }
        })
        .wait()
        .map_err(|e| FleetError::Zenoh(format!("declaring the probe {key}: {e}")))
}

/// This machine's address on the route to the first of `connect` (a Zenoh
/// endpoint `proto/host:port`) that resolves: the address the hub sees it
/// come from (no packet is sent: a UDP socket is only connected, so the
/// system picks the route). `None` when none resolves or has a route.
pub fn local_address_towards(connect: &[String]) -> Option<String> {
    use std::net::{ToSocketAddrs, UdpSocket};
    connect.iter().find_map(|e| {
        // Zenoh's `#bind=ADDRESS:PORT`: the link leaves from there.
        if let Some((_, config)) = e.split_once('#')
            && let Some(bind) = config.split(';').find_map(|kv| kv.strip_prefix("bind="))
            && let Ok(at) = bind.parse::<std::net::SocketAddr>()
        {
            return Some(at.ip().to_string());
        }
        let (_, address) = echelon::scenario::endpoint_address(e)?;
        let remote = address.to_socket_addrs().ok()?.next()?;
        let any = if remote.is_ipv4() {
            "0.0.0.0:0"
        } else {
            "[::]:0"
        };
        let socket = UdpSocket::bind(any).ok()?;
        socket.connect(remote).ok()?;
        Some(socket.local_addr().ok()?.ip().to_string())
    })
}

/// One answered round: when the query left (wall clock, ns), how long the
/// answer took (monotonic, ns) and the answerer's wall clock (ns).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Round {
    /// The asker's wall clock when the query left, ns since the epoch.
    pub sent_unix_ns: u64,
    /// The round trip, ns.
    pub rtt_ns: u64,
    /// The answerer's wall clock in its answer, ns since the epoch.
    pub remote_unix_ns: u64,
}

impl Round {
    /// The answerer's clock minus the asker's, s: `t_remote − (t_send +
    /// rtt / 2)`.
    pub fn offset(&self) -> f64 {
        let mid = i128::from(self.sent_unix_ns) + i128::from(self.rtt_ns) / 2;
        (i128::from(self.remote_unix_ns) - mid) as f64 * 1e-9
    }

    /// The round trip, s.
    pub fn rtt(&self) -> f64 {
        self.rtt_ns as f64 * 1e-9
    }
}

/// What [`ask`] measured of one process.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ProbeStats {
    /// The liveliness name asked.
    pub name: String,
    /// Queries sent.
    pub rounds: u32,
    /// Queries answered in time.
    pub answered: u32,
    /// Answers that were not a [`ProbeAnswer`] (not counted as answered).
    pub malformed: u32,
    /// Share of the rounds not answered, 0 to 1.
    pub loss: f64,
    /// Median round trip, s (`None`: nothing answered).
    pub rtt_p50: Option<f64>,
    /// 99th-percentile round trip (nearest rank), s.
    pub rtt_p99: Option<f64>,
    /// The answerer's wall clock minus the asker's, s: the median of the
    /// rounds' estimates.
    pub offset: Option<f64>,
    /// The last answer.
    pub answer: Option<ProbeAnswer>,
}

/// The nearest-rank `q` quantile of `sorted` (ascending, non-empty).
fn quantile(sorted: &[f64], q: f64) -> f64 {
    let rank = (q * sorted.len() as f64).ceil() as usize;
    sorted[rank.clamp(1, sorted.len()) - 1]
}

/// The median of `values` (`None`: empty); the mean of the two middle
/// values of an even count.
fn median(values: &mut [f64]) -> Option<f64> {
    values.sort_by(f64::total_cmp);
    let n = values.len();
    match n {
        0 => None,
        _ if n % 2 == 1 => Some(values[n / 2]),
        _ => Some(0.5 * (values[n / 2 - 1] + values[n / 2])),
    }
}

/// The stats of `rounds` queries to `name` of which `answered` were
/// answered (`malformed` answers besides), `answer` the last answer.
pub fn summarize(
    name: &str,
    rounds: u32,
    answered: &[Round],
    malformed: u32,
    answer: Option<ProbeAnswer>,
) -> ProbeStats {
    let mut rtts: Vec<f64> = answered.iter().map(Round::rtt).collect();
    rtts.sort_by(f64::total_cmp);
    let mut offsets: Vec<f64> = answered.iter().map(Round::offset).collect();
    let n = answered.len() as u32;
    ProbeStats {
        name: name.to_owned(),
        rounds,
        answered: n,
        malformed,
        loss: match rounds {
            0 => 0.0,
            r => f64::from(r.saturating_sub(n)) / f64::from(r),
        },
        rtt_p50: (!rtts.is_empty()).then(|| quantile(&rtts, 0.5)),
        rtt_p99: (!rtts.is_empty()).then(|| quantile(&rtts, 0.99)),
        offset: median(&mut offsets),
        answer,
    }
}

/// What the rounds of one [`ask`] collected.
#[derive(Debug, Default)]
struct Collected {
    /// Per round, its first valid answer.
    rounds: Vec<Option<Round>>,
    /// Per round, whether its query is final (answered by every
    /// queryable, or timed out).
    finished: Vec<bool>,
    malformed: u32,
    answer: Option<ProbeAnswer>,
}

/// Marks round `.1` final when dropped: Zenoh drops a query's callback
/// once the query is final, at once when no queryable matches.
struct Final(Arc<Mutex<Collected>>, usize);

impl Drop for Final {
    fn drop(&mut self) {
        if let Ok(mut c) = self.0.lock() {
            c.finished[self.1] = true;
        }
    }
}

/// Asks the probe of `name` (a liveliness name, `robot/3`, `router`) in the
/// fleet of `keys`: `rounds` queries, one every `interval`, each answered
/// within `timeout` or lost. Returns once every round is answered or timed
/// out. Only the first answer to each round counts (several routers of
/// linked sites all answer `router`'s).
pub fn ask(
    session: &zenoh::Session,
    keys: &Keys,
    name: &str,
    rounds: u32,
    interval: Duration,
    timeout: Duration,
) -> Result<ProbeStats, FleetError> {
    let key = keys.probe(name);
    let collected = Arc::new(Mutex::new(Collected {
        rounds: vec![None; rounds as usize],
        finished: vec![false; rounds as usize],
        ..Collected::default()
    }));
    let mut last_sent = Instant::now();
    for i in 0..rounds as usize {
        if i > 0 {
            std::thread::sleep(interval);
        }
        let round = Final(collected.clone(), i);
        let sent = Instant::now();
        let sent_unix_ns = crate::unix_nanos();
        last_sent = sent;
        session
            .get(&key)
            .target(zenoh::query::QueryTarget::All)
            .consolidation(zenoh::query::ConsolidationMode::None)
            .timeout(timeout)
            .callback(move |reply| {
                let rtt_ns = sent.elapsed().as_nanos() as u64;
                let Ok(sample) = reply.result() else {
                    return;
                };
                let Ok(mut c) = round.0.lock() else {
                    return;
                };
                match serde_json::from_slice::<ProbeAnswer>(&sample.payload().to_bytes()) {
                    Ok(answer) => {
                        if c.rounds[i].is_none() {
                            c.rounds[i] = Some(Round {
                                sent_unix_ns,
                                rtt_ns,
                                remote_unix_ns: answer.unix_ns,
                            });
                        }
                        c.answer = Some(answer);
                    }
                    Err(_) => c.malformed += 1,
                }
            })
            .wait()
            .map_err(|e| FleetError::Zenoh(format!("asking {key}: {e}")))?;
    }
    // Every round answered or final, or the last one's time is up.
    while last_sent.elapsed() < timeout {
        let done = collected
            .lock()
            .map(|c| {
                (c.rounds.iter().zip(&c.finished)).all(|(answer, fin)| answer.is_some() || *fin)
            })
            .unwrap_or(true);
        if done {
            break;
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    let c = collected
        .lock()
        .map_err(|_| FleetError::Config("probe: poisoned".into()))?;
    let answered: Vec<Round> = c.rounds.iter().flatten().copied().collect();
    Ok(summarize(
        name,
        rounds,
        &answered,
        c.malformed,
        c.answer.clone(),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// A round to a clock `offset_ns` ahead, sent at `sent` with legs
    /// `out` and `back` ns (the answer made on arrival).
    fn round(sent: u64, offset_ns: i64, out: u64, back: u64) -> Round {
        Round {
            sent_unix_ns: sent,
            rtt_ns: out + back,
            remote_unix_ns: (sent + out).saturating_add_signed(offset_ns),
        }
    }

    proptest! {
        /// Over random offsets (±10 s) and asymmetric legs (0 to 0.5 s
        /// each), every round's estimate is within half its legs'
        /// difference of the truth, and the median of several rounds
        /// within half the largest difference; symmetric legs give the
        /// offset exactly (to rounding of one ns).
        #[test]
        fn the_offset_is_within_half_the_asymmetry(
            offset_ns in -10_000_000_000i64..10_000_000_000,
            start in 1_000_000_000_000_000_000u64..2_000_000_000_000_000_000,
            legs in prop::collection::vec((0u64..500_000_000, 0u64..500_000_000), 1..20),
        ) {
            let truth = offset_ns as f64 * 1e-9;
            let mut rounds = Vec::new();
            let mut worst: f64 = 0.0;
            for (i, (out, back)) in legs.iter().copied().enumerate() {
                let r = round(start + i as u64 * 1_000_000_000, offset_ns, out, back);
                let half = (out as f64 - back as f64).abs() * 0.5e-9;
                prop_assert!((r.offset() - truth).abs() <= half + 2e-9, "{:?}", r);
                worst = worst.max(half);
                let symmetric = round(r.sent_unix_ns, offset_ns, out, out);
                prop_assert!((symmetric.offset() - truth).abs() <= 1e-9);
                rounds.push(r);
            }
            let stats = summarize("robot/1", legs.len() as u32 + 2, &rounds, 0, None);
            let estimate = stats.offset.unwrap_or(f64::NAN);
            prop_assert!((estimate - truth).abs() <= worst + 2e-9, "{} vs {}", estimate, truth);
            prop_assert_eq!(stats.answered, legs.len() as u32);
            prop_assert!((stats.loss - 2.0 / (legs.len() as f64 + 2.0)).abs() < 1e-12);
            let (p50, p99) = (stats.rtt_p50.unwrap_or(-1.0), stats.rtt_p99.unwrap_or(-1.0));
            let max = legs.iter().map(|(o, b)| (o + b) as f64 * 1e-9).fold(0.0, f64::max);
            prop_assert!(0.0 <= p50 && p50 <= p99 && p99 <= max + 1e-12);
        }
    }

    #[test]
    fn nothing_answered_is_all_lost() {
        let stats = summarize("router", 5, &[], 1, None);
        assert_eq!(stats.loss, 1.0);
        assert_eq!((stats.rtt_p50, stats.offset), (None, None));
        assert_eq!(stats.malformed, 1);
        let three = [1.0, 2.0, 3.0];
        assert_eq!(quantile(&three, 0.5), 2.0);
        assert_eq!(quantile(&three, 0.99), 3.0);
        assert_eq!(median(&mut [4.0, 1.0, 3.0, 2.0]), Some(2.5));
    }

    /// A probe declared on one session answers another's: the member, this
    /// build's version, and a clock offset of the same machine's within
    /// half the round trip of zero; a name nobody answers is all lost,
    /// within the timeout.
    #[test]
    fn a_declared_probe_answers_over_zenoh() {
        let (endpoint, stop, router) = crate::testing::serve_on_loopback(|net, stop| {
            crate::router::run(
                &crate::router::RouterOptions {
                    net: net.clone(),
                    max_wall: Some(Duration::from_secs(30)),
                    die_at: None,
                },
                stop,
            )
        });
        let client = || {
            crate::net::open(&crate::net::NetOptions {
                mode: Some(crate::net::Mode::Client),
                connect: vec![endpoint.clone()],
                ..crate::net::NetOptions::default()
            })
            .unwrap_or_else(|e| panic!("{e}"))
        };
        let (a, b) = (client(), client());
        let keys = Keys::new("lab");
        let _probe = declare(&a, &keys, Member::Robot(2)).unwrap_or_else(|e| panic!("{e}"));
        let ms = Duration::from_millis;
        let started = Instant::now();
        // Each asked until it answers (the declarations take a moment to
        // reach the asker).
        let until_answered = |name: &str, rounds: u32| loop {
            let s =
                ask(&b, &keys, name, rounds, ms(20), ms(1000)).unwrap_or_else(|e| panic!("{e}"));
            if s.answered == rounds || started.elapsed() > Duration::from_secs(20) {
                break s;
            }
            std::thread::sleep(ms(50));
        };
        let stats = until_answered("robot/2", 10);
        assert_eq!(stats.answered, 10, "{stats:?}");
        let answer = stats.answer.clone().unwrap_or_else(|| panic!("{stats:?}"));
        assert_eq!(
            (answer.member.as_str(), answer.version.as_str()),
            ("robot/2", VERSION)
        );
        assert_eq!(answer.pid, std::process::id());
        let (offset, rtt) = (stats.offset.unwrap_or(1.0), stats.rtt_p99.unwrap_or(1.0));
        assert!(offset.abs() <= rtt / 2.0 + 1e-3, "{stats:?}");
        // The router answers for every fleet.
        let hub = until_answered("router", 3);
        assert_eq!(hub.answered, 3, "{hub:?}");
        // A name nobody answers: all lost, without waiting out the
        // timeout (the router says at once that no queryable matches).
        let nobody = Instant::now();
        let none = ask(&b, &keys, "robot/9", 3, ms(10), ms(5000)).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!((none.answered, none.loss), (0, 1.0));
        assert!(
            nobody.elapsed() < Duration::from_secs(3),
            "{:?}",
            nobody.elapsed()
        );
        stop.raise();
        let _ = router.join();
    }
}
