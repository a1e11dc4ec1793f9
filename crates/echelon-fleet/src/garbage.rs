//! `echelon fleet garbage`: a rehearsal of hostile network input. From
//! fleet time `from` for `length` s it puts, on every key of the fleet it
//! has heard (`echelon/<fleet>/**`: the reference, every robot's state and
//! counters, latches…), at each of its ticks: random bytes of a random
//! length, the key's newest payload again (a duplicate) and one about a
//! second old (a replay). Everything it receives is the fleet's own
//! traffic; it learns the fleet's time from the reference. A fleet must
//! count and refuse all of it and follow on as if nothing happened (the
//! fault matrix's `garbage` row); in secure mode the routers refuse its
//! puts outright.

use std::collections::BTreeMap;

use serde::Serialize;

use echelon::rng::SplitMix64;

use crate::clock::ReferenceTime;
use crate::keys::Keys;
use crate::options::{ProcessOptions, Resolved};
use crate::runtime::{Flow, Outputs, Sample, Task};
use crate::{FleetError, StopFlag, net, runtime};

/// Ticks per fleet second.
const RATE: f64 = 20.0;
/// The most keys it keeps (a fleet of robots has a few per robot).
const MAX_KEYS: usize = 256;
/// The longest garbage payload, bytes.
const MAX_GARBAGE: usize = 96;
/// How old a replayed payload is, fleet s.
const REPLAY_AGE: f64 = 1.0;

/// What it put.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize)]
pub struct GarbageReport {
    /// Random payloads put.
    pub garbage: u64,
    /// Newest payloads put again.
    pub duplicates: u64,
    /// Payloads about a second old (`REPLAY_AGE`) put again.
    pub replays: u64,
    /// Keys it heard.
    pub keys: u64,
}

/// One key's newest payload, and an older one with its fleet time.
#[derive(Debug, Clone, Default)]
struct Heard {
    newest: Vec<u8>,
    old: Option<(f64, Vec<u8>)>,
    aging: Option<(f64, Vec<u8>)>,
}

/// `fleet garbage` as a [`Task`].
#[derive(Debug)]
pub struct GarbageTask {
    keys: Keys,
    from: f64,
    until: f64,
    rng: SplitMix64,
    heard: BTreeMap<String, Heard>,
    /// The fleet's time, from the reference.
    fleet: ReferenceTime,
    next: f64,
    report: GarbageReport,
    /// Its garbage starts with these 8 random bytes: it hears its own
    /// puts too, and records none of them.
    marker: [u8; 8],
}

impl GarbageTask {
    /// Garbage on the fleet of `keys` in fleet time `[from, from + length)`,
    /// drawn from `seed`.
    pub fn new(keys: Keys, from: f64, length: f64, seed: u64) -> Self {
        GarbageTask {
            keys,
            from,
            until: from + length,
            rng: SplitMix64::new(seed),
            heard: BTreeMap::new(),
            fleet: ReferenceTime::default(),
            next: 0.0,
            report: GarbageReport::default(),
            marker: SplitMix64::new(seed ^ 0x6761_7262_6167_6521)
                .next_u64()
                .to_le_bytes(),
        }
    }

    /// Its marker, then random bytes: `MARKER..=MAX_GARBAGE` bytes.
    fn garbage(&mut self) -> Vec<u8> {
        let len = self.marker.len()
            + (self.rng.next_u64() % (MAX_GARBAGE - self.marker.len() + 1) as u64) as usize;
        let mut g = self.marker.to_vec();
        g.extend((self.marker.len()..len).map(|_| self.rng.next_u64() as u8));
        g
    }
}

impl Task for GarbageTask {
    type Report = GarbageReport;

    fn inputs(&self) -> Vec<String> {
        vec![self.keys.everything()]
    }

    fn outputs(&self) -> Vec<String> {
        Vec::new()
    }

    /// Records the fleet's traffic (and the fleet's time from the
    /// reference), not what it put itself.
    fn on_input(&mut self, _input: usize, s: &Sample<'_>) -> Result<(), FleetError> {
        if s.payload.starts_with(&self.marker) {
            return Ok(());
        }
        if s.key == self.keys.reference() {
            self.fleet.hear(s.payload, s.at);
        }
        let Some(t) = self.fleet.at(s.at) else {
            return Ok(());
        };
        if !self.heard.contains_key(s.key) && self.heard.len() >= MAX_KEYS {
            return Ok(());
        }
        let h = self.heard.entry(s.key.to_owned()).or_default();
        h.newest = s.payload.to_vec();
        // `aging` becomes `old` once it is REPLAY_AGE old.
        match &h.aging {
            Some((at, _)) if t - at >= REPLAY_AGE => {
                h.old = h.aging.take();
                h.aging = Some((t, s.payload.to_vec()));
            }
            None => h.aging = Some((t, s.payload.to_vec())),
            _ => {}
        }
        Ok(())
    }

    fn next_wake(&self) -> f64 {
        self.next
    }

    fn tick(&mut self, now: f64, out: &mut dyn Outputs) -> Result<Flow, FleetError> {
        self.next = now + 1.0 / RATE;
        let Some(t) = self.fleet.at(now) else {
            return Ok(Flow::Continue);
        };
        if t < self.from || t >= self.until {
            return Ok(Flow::Continue);
        }
        let keys: Vec<String> = self.heard.keys().cloned().collect();
        self.report.keys = keys.len() as u64;
        for key in keys {
            let junk = self.garbage();
            out.put(&key, &junk);
            self.report.garbage += 1;
            let Some(h) = self.heard.get(&key) else {
                continue;
            };
            let (newest, old) = (h.newest.clone(), h.old.as_ref().map(|(_, p)| p.clone()));
            out.put(&key, &newest);
            self.report.duplicates += 1;
            if let Some(old) = old {
                out.put(&key, &old);
                self.report.replays += 1;
            }
        }
        Ok(Flow::Continue)
    }

    fn stop(&mut self, _out: &mut dyn Outputs) -> Result<(), FleetError> {
        Ok(())
    }

    fn report(self) -> Result<GarbageReport, FleetError> {
        Ok(self.report)
    }
}

/// Runs `fleet garbage` on the fleet of `opts` until a signal (or its
/// `duration`).
pub fn run(
    opts: ProcessOptions,
    from: f64,
    length: f64,
    seed: u64,
    stop: &StopFlag,
) -> Result<GarbageReport, FleetError> {
    let Resolved { keys, .. } = opts.resolve()?;
    let task = GarbageTask::new(keys, from, length, seed ^ u64::from(net::rand_source()));
    runtime::run(task, &opts.net, opts.clock(), stop)
}
