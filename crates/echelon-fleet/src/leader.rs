//! `echelon fleet leader`: the virtual leader (paper section 5's "virtual
//! leader computer") publishing the scenario's reference at a fixed rate.
//!
//! The leader hears the fleet command ([`crate::command`]): while a stop is
//! in force its reference pauses (the samples keep coming, fresh, with the
//! reference held where it was when the stop came), and on a resume it goes
//! on from there, so the robots resume behind a leader that waited for them
//! instead of chasing one that went on. Interrupted (SIGINT, SIGTERM) before
//! its end, it first puts a fleet stop: robots stop within a control period
//! instead of playing out their link-loss policy. It obeys a resume only
//! with a valid proof of the operator token it was given
//! ([`crate::token`]; [`TOKEN_ENV`] for the process).

use std::time::Duration;

use serde::Serialize;

use echelon::control::LeaderMotion;
use echelon::reference::{Order, Reference, Trajectory};

use crate::command::{self, Change, CommandCounts, FleetCommand, Latch};
use crate::keys::{KeyKind, Keys};
use crate::net;
use crate::options::{ProcessOptions, Resolved};
use crate::role::Member;
use crate::runtime::{self, Flow, Latching, Outputs, Sample, Task, WaitFor};
use crate::token::{OperatorToken, TOKEN_ENV};
use crate::wire::{self, Header, Reference as WireReference};
use crate::{FleetError, StopFlag};

/// Options of the leader process.
#[derive(Debug, Clone)]
pub struct LeaderOptions {
    /// Scenario, clock, network and fleet name (`duration` absent: the
    /// scenario's `sim.duration`).
    pub process: ProcessOptions,
    /// Publication rate, Hz (absent: the scenario's `[fleet] reference_rate`).
    pub rate: Option<f64>,
    /// Before starting the clock, wait until these liveliness roles are present
    /// (e.g. `collector`, `robot/1`), at most `wait_timeout`.
    pub wait_for: Vec<String>,
    /// Longest wait for `wait_for`, real time.
    pub wait_timeout: Duration,
    /// A rehearsed rogue (`--rogue`, the secure mode's tests): it joins
    /// even though the fleet has a leader (a process that does not play
    /// by the rules, which only the access control stops).
    pub rogue: bool,
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
    /// Fleet time the reference was paused by fleet stops, s.
    pub paused: f64,
    /// What the fleet commands did.
    pub commands: CommandCounts,
    /// Whether it put a fleet stop when it was interrupted.
    pub stopped_the_fleet: bool,
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
    /// Fleet time the reference paused at (a fleet stop in force).
    paused_at: Option<f64>,
    /// Fleet time paused so far: the reference is evaluated at `t - shift`.
    shift: f64,
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
            paused_at: None,
            shift: 0.0,
        }
    }

    /// Holds the reference where it is at fleet time `t` (a fleet stop).
    pub fn pause(&mut self, t: f64) {
        if self.paused_at.is_none() {
            self.paused_at = Some(t);
        }
    }

    /// Goes on from where it paused, at fleet time `t` (a resume).
    pub fn resume(&mut self, t: f64) {
        if let Some(p) = self.paused_at.take() {
            self.shift += (t - p).max(0.0);
        }
    }

    /// Whether it is paused.
    pub fn is_paused(&self) -> bool {
        self.paused_at.is_some()
    }

    /// Fleet time paused so far (up to `t` for a pause in progress), s.
    pub fn paused(&self, t: f64) -> f64 {
        self.shift + self.paused_at.map_or(0.0, |p| (t - p).max(0.0))
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
        // The reference's own time: fleet time less the pauses.
        let tau = match self.paused_at {
            Some(p) if t >= p => p - self.shift,
            _ => t - self.shift,
        };
        let jet = self.reference.eval(tau, Order::Two);
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
            paused: self.paused(self.last_t),
            commands: CommandCounts::default(),
            stopped_the_fleet: false,
        }
    }
}

/// [`Leader`] as a [`Task`] of the fleet runtime: no inputs, the reference
/// out, its liveliness token held; its clock starts once every
/// `--wait-for` name is present.
#[derive(Debug, Clone)]
pub struct LeaderTask {
    leader: Leader,
    keys: Keys,
    wait_for: Option<WaitFor>,
    buf: Vec<u8>,
    clock_start_unix_ns: u64,
    latch: Latch,
    stopped_the_fleet: bool,
    /// `--die-at`: the process kills itself at this fleet time.
    die_at: Option<f64>,
    /// Whether it has ticked (it says what it lacks at its first tick).
    started: bool,
    /// Refused while the fleet has a leader (false: a rehearsed rogue).
    exclusive: bool,
}

impl LeaderTask {
    /// `leader` publishing in the fleet of `keys`.
    pub fn new(leader: Leader, keys: Keys) -> LeaderTask {
        LeaderTask {
            leader,
            keys,
            wait_for: None,
            buf: Vec::with_capacity(wire::REFERENCE_LEN),
            clock_start_unix_ns: 0,
            latch: Latch::new(),
            stopped_the_fleet: false,
            die_at: None,
            started: false,
            exclusive: true,
        }
    }

    /// The same, joining even though the fleet has a leader: a rehearsed
    /// rogue publisher (`--rogue`), for the access control's tests.
    pub fn rogue(self) -> LeaderTask {
        LeaderTask {
            exclusive: false,
            ..self
        }
    }

    /// The same, its process killing itself with SIGKILL at fleet time
    /// `die_at` (`--die-at`, the fault matrix's `kill -9`).
    pub fn dying_at(self, die_at: Option<f64>) -> LeaderTask {
        LeaderTask { die_at, ..self }
    }

    /// The same, obeying the resumes signed with `token` (none: refusing
    /// every resume).
    pub fn with_operator_token(self, token: Option<OperatorToken>) -> LeaderTask {
        LeaderTask {
            latch: Latch::with_token(token),
            ..self
        }
    }

    /// The same, starting its clock once `w` is present.
    pub fn waiting_for(self, w: WaitFor) -> LeaderTask {
        LeaderTask {
            wait_for: Some(w),
            ..self
        }
    }

    /// The leader.
    pub fn leader(&self) -> &Leader {
        &self.leader
    }

    /// The fleet command it is under.
    pub fn latch(&self) -> &Latch {
        &self.latch
    }

    fn follow_latch(&mut self, change: Change, t: f64) {
        match change {
            Change::Stopped => self.leader.pause(t),
            Change::Resumed => self.leader.resume(t),
            Change::Unchanged => {}
        }
    }
}

/// Its outputs: the reference, the fleet command.
const REFERENCE: usize = 0;
const COMMAND: usize = 1;
/// Its inputs: the fleet command, the robots' own stops (the latch answers: the next).
const COMMAND_IN: usize = 0;
/// The input number of the robots' own stops (their halt keys).
const HALTS_IN: usize = 1;

impl Task for LeaderTask {
    type Report = LeaderReport;

    fn inputs(&self) -> Vec<String> {
        vec![self.keys.command(), self.keys.halts()]
    }

    fn outputs(&self) -> Vec<String> {
        vec![self.keys.reference(), self.keys.command()]
    }

    fn latching(&self) -> Option<Latching> {
        Some(Latching {
            answer_on: vec![self.keys.latch(&Member::Leader.liveliness())],
            ask: self.keys.latches(),
        })
    }

    fn latched(&self, _: usize) -> Option<Vec<u8>> {
        Some(self.latch.latched().encode())
    }

    fn latch_changes(&self) -> Option<u64> {
        Some(self.latch.changes())
    }

    fn tokens(&self) -> Vec<String> {
        vec![self.keys.alive(&Member::Leader.liveliness())]
    }

    fn exclusive(&self) -> bool {
        self.exclusive
    }

    fn wait_for(&self) -> Option<WaitFor> {
        self.wait_for.clone()
    }

    fn started(&mut self, unix_ns: u64) {
        self.clock_start_unix_ns = unix_ns;
    }

    fn on_input(&mut self, input: usize, sample: &Sample<'_>) -> Result<(), FleetError> {
        let before = self.latch.counts();
        let change = match (input, self.keys.classify(sample.key)) {
            (COMMAND_IN, _) => self.latch.on_payload(sample.payload),
            // A robot's own stop (its base's hazard): stop-only.
            (HALTS_IN, KeyKind::Halt(k)) => self.latch.on_halt(k, sample.payload),
            (HALTS_IN, _) => Change::Unchanged,
            _ => self.latch.on_hearsay(sample.payload),
        };
        if let Some(note) = self.latch.resume_note(change, before) {
            eprintln!("{note}");
        }
        self.follow_latch(change, sample.at.max(0.0));
        Ok(())
    }

    /// Interrupted before its end (a signal, an error): puts a fleet stop
    /// first, numbered after every command it knows.
    fn stop(&mut self, out: &mut dyn Outputs) -> Result<(), FleetError> {
        if self.leader.next_due().is_none() {
            return Ok(());
        }
        let c = FleetCommand::new(
            command::Order::Stop,
            self.latch.seq() + 1,
            &Member::Leader.identity(),
            "the leader was interrupted",
        );
        out.publish(COMMAND, &c.encode())?;
        let t = self.leader.last_t;
        let change = self.latch.on_command(c);
        self.follow_latch(change, t);
        self.stopped_the_fleet = true;
        Ok(())
    }

    fn next_wake(&self) -> f64 {
        self.leader.next_due().unwrap_or(f64::NEG_INFINITY)
    }

    fn tick(&mut self, now: f64, out: &mut dyn Outputs) -> Result<Flow, FleetError> {
        crate::faults::die_if_due(self.die_at, now, "fleet leader");
        if !self.started {
            // Said here, not before its session opened: bad input is one line.
            self.started = true;
            if !self.latch.has_token() {
                eprintln!("leader: no operator token ({TOKEN_ENV}): it will refuse every resume");
            }
        }
        if self.leader.next_due().is_none() {
            return Ok(Flow::Stop);
        }
        if let Some((h, sample)) = self.leader.tick(now) {
            wire::encode_reference(&mut self.buf, h, &sample);
            out.publish(REFERENCE, &self.buf)?;
        }
        Ok(Flow::Continue)
    }

    fn report(self) -> Result<LeaderReport, FleetError> {
        Ok(LeaderReport {
            clock_start_unix_ns: self.clock_start_unix_ns,
            commands: self.latch.counts(),
            stopped_the_fleet: self.stopped_the_fleet,
            ..self.leader.report()
        })
    }
}

/// Publishes the reference until `duration` or the stop flag: [`LeaderTask`]
/// on the fleet runtime.
pub fn run(opts: LeaderOptions, stop: &StopFlag) -> Result<LeaderReport, FleetError> {
    let Resolved {
        plan,
        settings,
        keys,
    } = opts.process.resolve()?;
    let reference = plan.reference().clone();
    let rate = opts.rate.unwrap_or(settings.reference_rate);
    let duration = opts.process.duration.unwrap_or(plan.config().duration);
    let leader = Leader::new(reference, rate, duration, net::rand_source());
    let token = OperatorToken::from_env()?;
    let mut task = LeaderTask::new(leader, keys.clone());
    if opts.rogue {
        task = task.rogue();
    }
    let task = task
        .dying_at(opts.process.die_at)
        .with_operator_token(token)
        .waiting_for(WaitFor {
            keys,
            names: opts.wait_for,
            timeout: opts.wait_timeout,
        });
    runtime::run(task, &opts.process.net, opts.process.clock(), stop)
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
