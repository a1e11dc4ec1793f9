//! The operator heartbeat: a supervised run's deadman. When the scenario
//! asks for one (`[fleet] operator_heartbeat = T`), every robot holds
//! (commands zero, link status `held`) while no heartbeat arrived on
//! `echelon/<fleet>/operator/heartbeat` for `T` s, and follows again when
//! one does ([`crate::robot::Watchdog::Operator`]). `echelon fleet
//! heartbeat` sends them (four per `T`); `fleet up` starts one when the
//! scenario asks, as the operator's process: an operator's laptop that
//! sleeps, or a heartbeat process killed, holds the fleet within `T`.
//!
//! A heartbeat is 12 bytes: its sender's random source (u32) and its
//! number (u64), little-endian. A robot accepts one numbered above the
//! last of its source, or from a new source (a restarted sender).

use crate::clock::ReferenceTime;
use crate::keys::Keys;
use crate::options::{ProcessOptions, Resolved};
use crate::role::Member;
use crate::runtime::{Flow, Outputs, Task};
use crate::{FleetError, StopFlag, net, runtime};

/// A heartbeat's length, bytes.
pub const HEARTBEAT_LEN: usize = 12;
/// Heartbeats sent per deadline.
pub const PER_DEADLINE: f64 = 4.0;

/// One heartbeat.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Heartbeat {
    /// The sender's random source.
    pub source: u32,
    /// Its number, from 0.
    pub seq: u64,
}

impl Heartbeat {
    /// Its 12 bytes.
    pub fn encode(&self) -> [u8; HEARTBEAT_LEN] {
        let mut b = [0u8; HEARTBEAT_LEN];
        b[..4].copy_from_slice(&self.source.to_le_bytes());
        b[4..].copy_from_slice(&self.seq.to_le_bytes());
        b
    }

    /// A heartbeat from exactly [`HEARTBEAT_LEN`] bytes.
    pub fn decode(bytes: &[u8]) -> Option<Heartbeat> {
        let b: &[u8; HEARTBEAT_LEN] = bytes.try_into().ok()?;
        let (source, seq) = b.split_at(4);
        Some(Heartbeat {
            source: u32::from_le_bytes(source.try_into().ok()?),
            seq: u64::from_le_bytes(seq.try_into().ok()?),
        })
    }

    /// Whether it may be taken after `last`: newer from the same source,
    /// or from another source.
    pub fn follows(&self, last: &Heartbeat) -> bool {
        self.source != last.source || self.seq > last.seq
    }
}

/// `fleet heartbeat` as a [`Task`]: a heartbeat every `period` fleet s
/// until `duration`.
#[derive(Debug, Clone)]
pub struct HeartbeatTask {
    keys: Keys,
    source: u32,
    period: f64,
    duration: Option<f64>,
    die_at: Option<f64>,
    next: f64,
    seq: u64,
    /// The fleet's time, from the leader's reference: `--die-at` is a
    /// fleet time.
    fleet: ReferenceTime,
}

impl HeartbeatTask {
    /// Heartbeats for the deadline `deadline` s ([`PER_DEADLINE`] per
    /// deadline) under `source`, until `duration` (absent: a signal); the
    /// process kills itself at `die_at` (`--die-at`).
    pub fn new(
        keys: Keys,
        deadline: f64,
        source: u32,
        duration: Option<f64>,
        die_at: Option<f64>,
    ) -> Self {
        HeartbeatTask {
            keys,
            source,
            period: deadline / PER_DEADLINE,
            duration,
            die_at,
            next: 0.0,
            seq: 0,
            fleet: ReferenceTime::default(),
        }
    }

    /// Heartbeats sent.
    pub fn sent(&self) -> u64 {
        self.seq
    }
}

/// What `fleet heartbeat` reports when it stops.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct HeartbeatReport {
    /// Heartbeats sent.
    pub sent: u64,
    /// Seconds between two.
    pub period: f64,
}

impl Task for HeartbeatTask {
    type Report = HeartbeatReport;

    /// The leader's reference, for the fleet's time.
    fn inputs(&self) -> Vec<String> {
        vec![self.keys.reference()]
    }

    fn outputs(&self) -> Vec<String> {
        vec![self.keys.heartbeat()]
    }

    fn tokens(&self) -> Vec<String> {
        vec![self.keys.alive(&Member::Operator.liveliness())]
    }

    fn on_input(
        &mut self,
        _input: usize,
        sample: &crate::runtime::Sample<'_>,
    ) -> Result<(), FleetError> {
        self.fleet.hear(sample.payload, sample.at);
        Ok(())
    }

    fn next_wake(&self) -> f64 {
        self.next
    }

    fn tick(&mut self, now: f64, out: &mut dyn Outputs) -> Result<Flow, FleetError> {
        if let Some(t) = self.fleet.at(now) {
            crate::faults::die_if_due(self.die_at, t, "fleet heartbeat");
        }
        if self.duration.is_some_and(|d| now >= d) {
            return Ok(Flow::Stop);
        }
        if now >= self.next {
            let h = Heartbeat {
                source: self.source,
                seq: self.seq,
            };
            out.publish(0, &h.encode())?;
            self.seq += 1;
            self.next += self.period;
            if now - self.next > self.period {
                self.next = now + self.period;
            }
        }
        Ok(Flow::Continue)
    }

    fn stop(&mut self, _out: &mut dyn Outputs) -> Result<(), FleetError> {
        Ok(())
    }

    fn report(self) -> Result<HeartbeatReport, FleetError> {
        Ok(HeartbeatReport {
            sent: self.seq,
            period: self.period,
        })
    }
}

/// Runs `fleet heartbeat` for the scenario of `opts` (which must ask for
/// one: `[fleet] operator_heartbeat`) until its `duration` or a signal.
pub fn run(opts: ProcessOptions, stop: &StopFlag) -> Result<HeartbeatReport, FleetError> {
    let Resolved { settings, keys, .. } = opts.resolve()?;
    let Some(deadline) = settings.operator_heartbeat else {
        return Err(FleetError::Config(
            "the scenario asks for no operator heartbeat: give [fleet] operator_heartbeat = T (s)"
                .into(),
        ));
    };
    let task = HeartbeatTask::new(
        keys,
        deadline,
        net::rand_source(),
        opts.duration,
        opts.die_at,
    );
    runtime::run(task, &opts.net, opts.clock(), stop)
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        /// Any heartbeat round-trips; any other length is refused; a
        /// heartbeat follows an older one of its source, never the same or
        /// a newer one, and always one of another source.
        #[test]
        fn heartbeats_round_trip_and_order(source in any::<u32>(), seq in any::<u64>(),
                                           other in any::<u32>(), len in 0usize..40) {
            let h = Heartbeat { source, seq };
            prop_assert_eq!(Heartbeat::decode(&h.encode()), Some(h));
            if len != HEARTBEAT_LEN {
                prop_assert_eq!(Heartbeat::decode(&vec![0u8; len]), None);
            }
            prop_assert!(!h.follows(&h));
            if seq > 0 {
                let older = Heartbeat { source, seq: seq - 1 };
                prop_assert!(h.follows(&older));
                prop_assert!(!older.follows(&h));
            }
            if other != source {
                let another = Heartbeat { source: other, seq: u64::MAX };
                prop_assert!(h.follows(&another));
            }
        }
    }
}
