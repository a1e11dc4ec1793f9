//! `echelon fleet router`: a Zenoh router (the engine of `zenohd`, from the
//! `zenoh` crate) for a fleet's processes to link to: each keeps one link to
//! its site's router, which routes every sample for it; routers of several
//! sites link to each other. Runs until SIGINT/SIGTERM, then reports.
//!
//! The router also watches the fleets' liveliness tokens
//! (`echelon/*/alive/**`), so its report says how many processes were linked
//! through the router network at once (`members_peak`) and in all.
//!
//! Why it is not a [`Task`](crate::runtime::Task) on the runtime: a task is
//! a member of one fleet on a fleet clock (it subscribes to its inputs,
//! publishes on its outputs, holds its liveliness token and is ticked),
//! and a router is none of these. It routes the other processes' samples
//! inside Zenoh's own threads, belongs to no one fleet (it carries every
//! fleet's keys, and other sites' routers link to it), runs in real time
//! only, and what it reports comes from its session (its id, the routers
//! linked to it) and from a liveliness subscription on every fleet's
//! `alive/**`, not from samples handed to it. What it shares with the
//! runtime: the session ([`net::open`], in router mode, with the same
//! configuration and secure mode as every process), the stop flag polled
//! every [`runtime::NAP`], and a typed report ([`RouterReport`]) that
//! `fleet up` reads back as such.

use std::collections::BTreeSet;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use serde::Serialize;
use zenoh::Wait;
use zenoh::sample::SampleKind;

use crate::net::{self, Mode, NetOptions};
use crate::runtime;
use crate::{FleetError, StopFlag};

/// Options of `fleet router`.
#[derive(Debug, Clone, Default)]
pub struct RouterOptions {
    /// Listen and connect endpoints (other routers), secure mode; the mode is
    /// set to router.
    pub net: NetOptions,
    /// Stop after this much real time (tests); `None`: until the stop flag.
    pub max_wall: Option<Duration>,
    /// Kill itself with SIGKILL once a reference it forwards reaches this
    /// fleet time (`--die-at`: the fault matrix's router failure; it
    /// learns the fleet's time from the references passing through).
    pub die_at: Option<f64>,
}

/// What `fleet router` prints when it stops.
#[derive(Debug, Clone, Default, PartialEq, Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RouterReport {
    /// The router's Zenoh id.
    pub zid: String,
    /// The endpoints it listened on, as given.
    pub listen: Vec<String>,
    /// Real time it ran, s.
    pub uptime: f64,
    /// Fleet processes (liveliness tokens, any fleet) ever seen.
    pub members_joined: usize,
    /// Most fleet processes present at once.
    pub members_peak: usize,
    /// Fleet processes present when it stopped.
    pub members_at_exit: usize,
    /// Other routers linked to it when it stopped.
    pub routers_at_exit: usize,
}

#[derive(Debug, Default)]
struct Members {
    live: BTreeSet<String>,
    joined: BTreeSet<String>,
    peak: usize,
}

/// Runs a router until `stop` is raised (or `max_wall` passes).
pub fn run(opts: &RouterOptions, stop: &StopFlag) -> Result<RouterReport, FleetError> {
    let started = Instant::now();
    let net = NetOptions {
        mode: Some(Mode::Router),
        ..opts.net.clone()
    };
    let session = net::open(&net)?;
    // `fleet doctor`'s probe, for every fleet (the hub's clock is its
    // router's), first: clients may ask as soon as it listens.
    let _probe = crate::probe::declare(
        &session,
        &crate::keys::Keys::any(),
        crate::role::Member::Router,
    )?;
    let members: Arc<Mutex<Members>> = Arc::default();
    let sink = members.clone();
    let _sub = session
        .liveliness()
        .declare_subscriber(crate::keys::Keys::any().alive("**"))
        .history(true)
        .callback(move |s| {
            if let Ok(mut m) = sink.lock() {
                let key = s.key_expr().as_str().to_owned();
                if s.kind() == SampleKind::Put {
                    m.joined.insert(key.clone());
                    m.live.insert(key);
                    m.peak = m.peak.max(m.live.len());
                } else {
                    m.live.remove(&key);
                }
            }
        })
        .wait()
        .map_err(|e| FleetError::Zenoh(format!("liveliness: {e}")))?;
    // The fleet's time, for `--die-at`, from any fleet's reference.
    let _clock = match opts.die_at {
        Some(at) => Some(
            session
                .declare_subscriber(crate::keys::Keys::any().reference())
                .callback(move |s| {
                    if let Some(t) = crate::clock::ReferenceTime::of(&s.payload().to_bytes()) {
                        crate::faults::die_if_due(Some(at), t, "fleet router");
                    }
                })
                .wait()
                .map_err(|e| FleetError::Zenoh(format!("the reference: {e}")))?,
        ),
        None => None,
    };
    let listen = net.listen.clone();
    eprintln!("fleet router {} listening on {listen:?}", session.zid());
    while !stop.is_raised() && opts.max_wall.is_none_or(|m| started.elapsed() < m) {
        std::thread::sleep(runtime::NAP);
    }
    let routers_at_exit = session.info().routers_zid().wait().count();
    let (members_joined, members_peak, members_at_exit) = {
        let m = members
            .lock()
            .map_err(|_| FleetError::Config("poisoned".into()))?;
        (m.joined.len(), m.peak, m.live.len())
    };
    Ok(RouterReport {
        zid: session.zid().to_string(),
        listen,
        uptime: started.elapsed().as_secs_f64(),
        members_joined,
        members_peak,
        members_at_exit,
        routers_at_exit,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::serve_on_loopback;

    /// Two clients that know only the router exchange a sample through it,
    /// and the router counts their liveliness tokens.
    #[test]
    fn clients_talk_through_the_router() {
        let (endpoint, stop, router) = serve_on_loopback(|net, stop| {
            let max_wall = Some(Duration::from_secs(30));
            run(
                &RouterOptions {
                    net: net.clone(),
                    max_wall,
                    die_at: None,
                },
                stop,
            )
        });
        let client = || {
            net::open(&NetOptions {
                mode: Some(Mode::Client),
                connect: vec![endpoint.clone()],
                ..NetOptions::default()
            })
            .unwrap_or_else(|e| panic!("{e}"))
        };
        let (a, b) = (client(), client());
        let _ta = a
            .liveliness()
            .declare_token("echelon/t/alive/a")
            .wait()
            .unwrap_or_else(|e| panic!("{e}"));
        let _tb = b
            .liveliness()
            .declare_token("echelon/t/alive/b")
            .wait()
            .unwrap_or_else(|e| panic!("{e}"));
        let sub = b
            .declare_subscriber("echelon/t/x")
            .wait()
            .unwrap_or_else(|e| panic!("{e}"));
        let started = Instant::now();
        let got = loop {
            a.put("echelon/t/x", vec![7u8])
                .wait()
                .unwrap_or_else(|e| panic!("{e}"));
            if let Ok(Some(s)) = sub.recv_timeout(Duration::from_millis(100)) {
                break s.payload().to_bytes().to_vec();
            }
            assert!(started.elapsed() < Duration::from_secs(20), "no sample");
        };
        assert_eq!(got, vec![7u8]);
        // The only link of each client is to the router.
        assert_eq!(a.info().routers_zid().wait().count(), 1);
        assert_eq!(a.info().peers_zid().wait().count(), 0);
        std::thread::sleep(Duration::from_millis(200));
        stop.raise();
        let report = router
            .join()
            .unwrap_or_else(|_| panic!("router thread"))
            .unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(report.members_joined, 2, "{report:?}");
        assert_eq!(report.members_peak, 2, "{report:?}");
        assert_eq!(report.listen, vec![endpoint]);
    }
}
