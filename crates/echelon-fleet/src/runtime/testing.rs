//! A task for the tests of both runtimes (the in-memory bus and Zenoh).

use std::thread::ThreadId;

use super::{Flow, Outputs, Sample, Task, WaitFor};
use crate::FleetError;

/// One due tick of a [`Periodic`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Tick {
    /// When it ran, on the task's clock.
    pub(super) now: f64,
    /// The wake it was due at.
    pub(super) due: f64,
    /// The thread it ran on.
    pub(super) thread: ThreadId,
    /// Samples heard before it.
    pub(super) heard: usize,
}

/// A task ticking every `period` (its clock) until it has ticked `ticks`
/// times when due. Each due tick is logged and publishes the number of
/// ticks before it ([`count`]) on its one output; every sample it hears
/// through its one input is kept (time, key, payload).
#[derive(Debug)]
pub(super) struct Periodic {
    period: f64,
    ticks: usize,
    next: f64,
    input: String,
    output: String,
    /// What it waits for before its clock starts.
    pub(super) wait_for: Option<WaitFor>,
    /// Its due ticks.
    pub(super) log: Vec<Tick>,
    /// The samples it heard: time on its clock, key, payload.
    pub(super) heard: Vec<(f64, String, Vec<u8>)>,
}

impl Periodic {
    /// Ticks every `period` s `ticks` times, hearing `input` (a key
    /// expression) and publishing on `output`.
    pub(super) fn new(period: f64, ticks: usize, input: &str, output: &str) -> Periodic {
        Periodic {
            period,
            ticks,
            next: 0.0,
            input: input.to_owned(),
            output: output.to_owned(),
            wait_for: None,
            log: Vec::new(),
            heard: Vec::new(),
        }
    }
}

/// The tick count a [`Periodic`] published.
pub(super) fn count(payload: &[u8]) -> u64 {
    u64::from_le_bytes(payload.try_into().unwrap_or_default())
}

impl Task for Periodic {
    /// Its due ticks.
    type Report = usize;

    fn inputs(&self) -> Vec<String> {
        vec![self.input.clone()]
    }

    fn outputs(&self) -> Vec<String> {
        vec![self.output.clone()]
    }

    fn wait_for(&self) -> Option<WaitFor> {
        self.wait_for.clone()
    }

    fn on_input(&mut self, _input: usize, s: &Sample<'_>) -> Result<(), FleetError> {
        self.heard
            .push((s.at, s.key.to_owned(), s.payload.to_vec()));
        Ok(())
    }

    fn next_wake(&self) -> f64 {
        self.next
    }

    fn tick(&mut self, now: f64, out: &mut dyn Outputs) -> Result<Flow, FleetError> {
        if now < self.next {
            return Ok(Flow::Continue);
        }
        out.publish(0, &(self.log.len() as u64).to_le_bytes())?;
        self.log.push(Tick {
            now,
            due: self.next,
            thread: std::thread::current().id(),
            heard: self.heard.len(),
        });
        self.next += self.period;
        Ok(if self.log.len() >= self.ticks {
            Flow::Stop
        } else {
            Flow::Continue
        })
    }

    fn report(self) -> Result<usize, FleetError> {
        Ok(self.log.len())
    }
}
