//! `echelon fleet leader`: the virtual leader (paper section 5's "virtual
//! leader computer") publishing the scenario's reference at a fixed rate.

use std::collections::BTreeSet;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use serde::Serialize;
use zenoh::Wait;
use zenoh::sample::SampleKind;

use echelon::control::LeaderMotion;
use echelon::reference::{Order, Reference, Trajectory};
use echelon::scenario::{Overrides, Scenario};

use crate::clock::FleetClock;
use crate::keys::Keys;
use crate::net::{self, NetOptions};
use crate::wire::{self, Header, Reference as WireReference};
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
#[derive(Debug, Clone, Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LeaderReport {
    /// [`crate::role::Role::Leader`].
    pub role: crate::role::Role,
    /// Reference samples published.
    pub published: u64,
    /// Fleet time of the last sample, s.
    pub t: f64,
    /// Samples published more than a period late.
    pub late: u64,
    /// When every `--wait-for` role had joined and the clock started, UNIX
    /// ns (`fleet up`'s startup time ends here).
    pub clock_start_unix_ns: u64,
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

/// The virtual leader as a state machine: sample `k` of the reference is due
/// at fleet time `k / rate`, up to `duration`. It has no inputs; the caller
/// ticks it with the time it reads and publishes what it returns.
#[derive(Debug, Clone)]
pub struct Leader {
    reference: Reference,
    period: f64,
    duration: f64,
    source: u32,
    k: u64,
    late: u64,
    last_t: f64,
}

impl Leader {
    /// A leader publishing `reference` at `rate` Hz until fleet time
    /// `duration`, under the random `source`.
    pub fn new(reference: Reference, rate: f64, duration: f64, source: u32) -> Leader {
        Leader {
            reference,
            period: 1.0 / rate,
            duration,
            source,
            k: 0,
            late: 0,
            last_t: 0.0,
        }
    }

    /// Fleet time of the next sample, or `None` once past `duration`.
    pub fn next_due(&self) -> Option<f64> {
        let t = self.k as f64 * self.period;
        (t <= self.duration + 1e-9).then_some(t)
    }

    /// At fleet time `now`: the sample due, with its header (`None` before it
    /// is due, or after the end). A sample sent more than a period late is
    /// counted.
    pub fn tick(&mut self, now: f64) -> Option<(Header, WireReference)> {
        let t = self.next_due()?;
        if now < t {
            return None;
        }
        if now - t > self.period {
            self.late += 1;
        }
        let jet = self.reference.eval(t, Order::Two);
        let sample = WireReference {
            t,
            motion: LeaderMotion::of_jet(&jet),
            speed: jet.speed(),
            turn_rate: jet.turn_rate(),
        };
        let h = Header {
            source: self.source,
            seq: self.k,
        };
        self.k += 1;
        self.last_t = t;
        Some((h, sample))
    }

    /// What the leader reports when it stops.
    pub fn report(&self) -> LeaderReport {
        LeaderReport {
            role: crate::role::Role::Leader,
            published: self.k,
            t: self.last_t,
            late: self.late,
            clock_start_unix_ns: 0,
        }
    }
}

/// Publishes the reference until `duration` or the stop flag: the Zenoh
/// driver of [`Leader`].
pub fn run(opts: LeaderOptions, stop: &StopFlag) -> Result<LeaderReport, FleetError> {
    let fleet = opts.scenario.fleet()?;
    let built = opts.scenario.build(&Overrides::default())?;
    let reference = built.plan.reference().clone();
    let rate = opts.rate.unwrap_or(fleet.reference_rate);
    let duration = opts.duration.unwrap_or(built.plan.config().duration);
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
    let clock_start_unix_ns = crate::unix_nanos();
    let mut leader = Leader::new(reference, rate, duration, net::rand_source());
    let mut buf = Vec::with_capacity(wire::REFERENCE_LEN);
    while !stop.is_raised() {
        let Some(t) = leader.next_due() else {
            break;
        };
        clock.sleep_until(t, Duration::from_millis(20));
        if let Some((h, sample)) = leader.tick(clock.now()) {
            wire::encode_reference(&mut buf, h, &sample);
            net::publish(&session, &publisher, &buf)?;
        }
    }
    drop(publisher);
    let _ = session.close().wait();
    Ok(LeaderReport {
        clock_start_unix_ns,
        ..leader.report()
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::circle;

    #[test]
    fn samples_are_due_on_the_rate_grid_and_late_ones_are_counted() {
        let c = circle([0.0, 0.0], 0.0, 0.2, 0.2);
        let mut l = Leader::new(Reference::Circle(c), 50.0, 0.1, 7);
        assert_eq!(l.next_due(), Some(0.0));
        assert!(l.tick(-0.001).is_none());
        let (h, r) = l.tick(0.0).unwrap_or_else(|| panic!("due"));
        assert_eq!((h.source, h.seq, r.t), (7, 0, 0.0));
        assert_eq!(r.motion, LeaderMotion::of_jet(&c.eval(0.0, Order::Two)));
        assert!(l.tick(0.019).is_none());
        // Sample 1 (t = 0.02) sent at 0.05: more than a period late.
        let (h, r) = l.tick(0.05).unwrap_or_else(|| panic!("due"));
        assert_eq!((h.seq, r.t), (1, 0.02));
        let mut n = 2;
        while let Some(t) = l.next_due() {
            assert!(l.tick(t).is_some());
            n += 1;
        }
        // 0, 0.02, …, 0.1: six samples, then nothing.
        assert_eq!(n, 6);
        assert!(l.tick(10.0).is_none());
        let rep = l.report();
        assert_eq!((rep.published, rep.late), (6, 1));
        assert!((rep.t - 0.1).abs() < 1e-12);
    }
}
