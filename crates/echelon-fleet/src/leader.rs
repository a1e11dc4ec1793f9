//! `echelon fleet leader`: the virtual leader (paper section 5's "virtual
//! leader computer") publishing the scenario's reference at a fixed rate.

use std::collections::BTreeSet;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use serde::Serialize;
use zenoh::Wait;
use zenoh::sample::SampleKind;

use echelon::control::LeaderMotion;
use echelon::reference::{Order, Trajectory};
use echelon::scenario::{Overrides, Scenario};

use crate::clock::FleetClock;
use crate::keys::Keys;
use crate::net::{self, NetOptions};
use crate::wire::{self, Header, Reference};
use crate::{FleetError, StopFlag};

/// Options of the leader process.
#[derive(Debug, Clone)]
pub struct LeaderOptions {
    /// The scenario.
    pub scenario: Scenario,
    /// Publication rate, Hz (absent: the scenario's `[fleet] reference_rate`).
    pub rate: Option<f64>,
    /// Clock speed-up `K`.
    pub time_scale: f64,
    /// Stop after this fleet time (absent: the scenario's `sim.duration`).
    pub duration: Option<f64>,
    /// Before starting the clock, wait until these liveliness roles are present
    /// (e.g. `collector`, `robot/1`), at most `wait_timeout`.
    pub wait_for: Vec<String>,
    /// Longest wait for `wait_for`, real time.
    pub wait_timeout: Duration,
    /// Network.
    pub net: NetOptions,
    /// Fleet name (absent: the scenario's).
    pub fleet: Option<String>,
}

/// What the leader reports when it stops (one JSON line on stdout).
#[derive(Debug, Clone, Serialize)]
pub struct LeaderReport {
    /// `leader`.
    pub role: &'static str,
    /// Reference samples published.
    pub published: u64,
    /// Fleet time of the last sample, s.
    pub t: f64,
    /// Samples published more than a period late.
    pub late: u64,
}

/// Waits until every role of `roles` has a liveliness token under
/// `echelon/<fleet>/alive/`, or `timeout` passes.
fn wait_for_roles(
    session: &zenoh::Session,
    keys: &Keys,
    roles: &[String],
    timeout: Duration,
    stop: &StopFlag,
) -> Result<(), FleetError> {
    if roles.is_empty() {
        return Ok(());
    }
    let seen: Arc<Mutex<BTreeSet<String>>> = Arc::default();
    let sink = seen.clone();
    let prefix = keys.alive("");
    let _sub = session
        .liveliness()
        .declare_subscriber(keys.alive("**"))
        .history(true)
        .callback(move |s| {
            if s.kind() == SampleKind::Put
                && let Some(role) = s.key_expr().as_str().strip_prefix(&prefix)
                && let Ok(mut set) = sink.lock()
            {
                set.insert(role.to_owned());
            }
        })
        .wait()
        .map_err(|e| FleetError::Zenoh(format!("liveliness: {e}")))?;
    let started = Instant::now();
    loop {
        let missing: Vec<String> = {
            let set = seen
                .lock()
                .map_err(|_| FleetError::Config("poisoned".into()))?;
            roles
                .iter()
                .filter(|r| !set.contains(*r))
                .cloned()
                .collect()
        };
        if missing.is_empty() {
            // Let the declarations that came with the tokens settle.
            std::thread::sleep(Duration::from_millis(100));
            return Ok(());
        }
        if stop.is_raised() {
            return Ok(());
        }
        if started.elapsed() > timeout {
            return Err(FleetError::Config(format!(
                "waited {:.0} s for {} to join the fleet",
                timeout.as_secs_f64(),
                missing.join(", ")
            )));
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// Publishes the reference until `duration` or the stop flag.
pub fn run(opts: LeaderOptions, stop: &StopFlag) -> Result<LeaderReport, FleetError> {
    let fleet = opts.scenario.fleet()?;
    let built = opts.scenario.build(&Overrides::default())?;
    let reference = built.simulation.reference().clone();
    let rate = opts.rate.unwrap_or(fleet.reference_rate);
    let duration = opts.duration.unwrap_or(built.simulation.config().duration);
    let keys = Keys::new(opts.fleet.as_deref().unwrap_or(&fleet.name));

    let session = net::open(&opts.net)?;
    let publisher = session
        .declare_publisher(keys.reference())
        .wait()
        .map_err(|e| FleetError::Zenoh(format!("declaring the reference publisher: {e}")))?;
    let _token = session
        .liveliness()
        .declare_token(keys.alive("leader"))
        .wait()
        .map_err(|e| FleetError::Zenoh(format!("liveliness: {e}")))?;
    wait_for_roles(&session, &keys, &opts.wait_for, opts.wait_timeout, stop)?;

    let clock = FleetClock::new(opts.time_scale);
    let source = net::rand_source();
    let period = 1.0 / rate;
    let mut buf = Vec::with_capacity(wire::REFERENCE_LEN);
    let mut k: u64 = 0;
    let mut late: u64 = 0;
    let mut last_t = 0.0;
    while !stop.is_raised() {
        let t = k as f64 * period;
        if t > duration + 1e-9 {
            break;
        }
        clock.sleep_until(t, Duration::from_millis(20));
        let now = clock.now();
        if now < t {
            continue;
        }
        if now - t > period {
            late += 1;
        }
        let jet = reference.eval(t, Order::Two);
        let sample = Reference {
            t,
            motion: LeaderMotion::of_jet(&jet),
            speed: jet.speed(),
            turn_rate: jet.turn_rate(),
        };
        wire::encode_reference(&mut buf, Header { source, seq: k }, &sample);
        net::publish(&publisher, &buf)?;
        k += 1;
        last_t = t;
    }
    drop(publisher);
    let _ = session.close().wait();
    Ok(LeaderReport {
        role: "leader",
        published: k,
        t: last_t,
        late,
    })
}
