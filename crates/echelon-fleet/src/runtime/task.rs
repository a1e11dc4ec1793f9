//! What a role is to the runtime: a [`Task`], after copper-rs tasks and
//! sans-IO protocol crates. It reads no clock, opens no socket and sleeps
//! nowhere: it is handed what arrives ([`Task::on_input`]) and ticked at its
//! [next wake](Task::next_wake), both with the time the runtime reads, and
//! it writes what it sends to [`Outputs`].

use std::time::Duration;

use serde::Serialize;

use crate::FleetError;
use crate::keys::Keys;

use super::Linger;

/// [`Task::queue`] unless a task says otherwise: a controller's inputs
/// between two ticks, with room for bursts.
pub const DEFAULT_QUEUE: usize = 4096;

/// One sample handed to a task.
#[derive(Debug, Clone, Copy)]
pub struct Sample<'a> {
    /// Its key.
    pub key: &'a str,
    /// Its payload.
    pub payload: &'a [u8],
    /// Its attachment, if any (rmw_zenoh's on ROS 2 samples).
    pub attachment: Option<&'a [u8]>,
    /// When it arrived, on the task's clock (s).
    pub at: f64,
    /// When it arrived, UNIX ns (wall clock; on the bus, `at` in ns).
    pub unix_ns: u64,
    /// Its delay since the sender stamped it, ns (`None`: not stamped).
    pub delay: Option<i64>,
}

/// What the runtime does after a tick.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Flow {
    /// Keep going.
    Continue,
    /// The task is done: stop it.
    Stop,
}

/// One message a task sends: its payload on its output number `output` (an
/// index into [`Task::outputs`]), with rmw_zenoh's attachment for a ROS 2
/// peer.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Outgoing<'a> {
    /// The task's output it goes on.
    pub output: usize,
    /// The payload.
    pub payload: &'a [u8],
    /// An attachment (`None`: the runtime stamps it with the sender's
    /// timestamp instead).
    pub attachment: Option<&'a [u8]>,
}

/// Where a task's messages go: Zenoh ([`super::run`]) or the in-memory
/// bus ([`super::bus`]).
pub trait Outputs {
    /// Sends `message`: without an attachment stamped with the sender's
    /// timestamp, with one unstamped (as rmw_zenoh does).
    fn send(&mut self, message: Outgoing<'_>) -> Result<(), FleetError>;
    /// Publishes `payload` on output `output`, stamped.
    fn publish(&mut self, output: usize, payload: &[u8]) -> Result<(), FleetError> {
        self.send(Outgoing {
            output,
            payload,
            attachment: None,
        })
    }
    /// Publishes `payload` with `attachment` on output `output`, unstamped.
    fn publish_attached(
        &mut self,
        output: usize,
        payload: &[u8],
        attachment: &[u8],
    ) -> Result<(), FleetError> {
        self.send(Outgoing {
            output,
            payload,
            attachment: Some(attachment),
        })
    }
    /// Puts `payload` on `key`, stamped, without a declared publisher; best
    /// effort (errors are ignored).
    fn put(&mut self, key: &str, payload: &[u8]);
}

/// Output number `output` of `outputs` (a task's, as [`Task::outputs`]
/// orders them: keys, publishers), or an error naming it.
pub(crate) fn declared<T>(outputs: &[T], output: usize) -> Result<&T, FleetError> {
    outputs
        .get(output)
        .ok_or_else(|| FleetError::Zenoh(format!("no output {output}")))
}

/// Liveliness names to wait for before a task's clock starts.
#[derive(Debug, Clone)]
pub struct WaitFor {
    /// The fleet whose `alive/<name>` tokens are awaited.
    pub keys: Keys,
    /// The names ([`crate::role::Member::liveliness`]).
    pub names: Vec<String>,
    /// The longest wait, real time.
    pub timeout: Duration,
}

/// A latch a task holds and asks for at its start (the fleet command,
/// [`crate::command`]).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Latching {
    /// The keys it answers queries on, the `i`-th with
    /// [`Task::latched`]`(i)`: one, or one per member of a
    /// [host](crate::host).
    pub answer_on: Vec<String>,
    /// The key expression it queries once, before its clock starts; each
    /// answer (but its own) is handed to [`Task::on_input`] as input number
    /// `inputs().len()`, once its clock reads 0.
    pub ask: String,
}

/// A fleet role's behaviour, whatever carries its messages.
///
/// The runtime subscribes to [`inputs`](Task::inputs), declares
/// [`outputs`](Task::outputs) and [`tokens`](Task::tokens), waits for
/// [`wait_for`](Task::wait_for), then until the task stops (or a stop
/// request): hands it every sample that arrived ([`on_input`], with its
/// arrival time) and ticks it at its next wake ([`tick`]). Then it
/// [stops](Task::stop) it (with the outputs still open) and takes its
/// [report](Task::report).
///
/// [`on_input`]: Task::on_input
/// [`tick`]: Task::tick
pub trait Task {
    /// What it reports when it stops: typed, serialised across processes.
    type Report: Serialize;

    /// The key expressions it subscribes to; [`Task::on_input`] is told the
    /// index of the one a sample came through.
    fn inputs(&self) -> Vec<String>;

    /// The keys it publishes on (declared publishers), by index.
    fn outputs(&self) -> Vec<String>;

    /// The liveliness tokens it holds while it runs (full key expressions).
    fn tokens(&self) -> Vec<String> {
        Vec::new()
    }

    /// Whether its tokens name a member the fleet has only one of (the
    /// leader, robot K, base K): the runtime refuses to run it while
    /// another process holds one of them (a second `fleet up`, a robot
    /// started twice), before it publishes anything.
    fn exclusive(&self) -> bool {
        false
    }

    /// The latch it holds and asks for (`None`: none).
    fn latching(&self) -> Option<Latching> {
        None
    }

    /// What it answers on its latch key number `i` now
    /// ([`Latching::answer_on`]; `None`: nothing).
    fn latched(&self, i: usize) -> Option<Vec<u8>> {
        let _ = i;
        None
    }

    /// A number that moves whenever what [`Task::latched`] answers changes:
    /// the runtime encodes the answer again only when it moved, not every
    /// tick. `None` (the default): unknown, so the answer is taken after
    /// every call.
    fn latch_changes(&self) -> Option<u64> {
        None
    }

    /// Who must be present before its clock starts.
    fn wait_for(&self) -> Option<WaitFor> {
        None
    }

    /// Whether it takes each sample as soon as it arrives (a recorder); else
    /// samples wait for its next wake (a controller), and the runtime does
    /// not wake up for each of them.
    fn wakes_on_input(&self) -> bool {
        false
    }

    /// How many samples may wait for it (between two ticks, or while it
    /// takes one); the next ones are dropped, counted and handed to
    /// [`Task::on_dropped`]: a Zenoh receiving thread never blocks on it.
    fn queue(&self) -> usize {
        DEFAULT_QUEUE
    }

    /// `total` samples were dropped so far because more than
    /// [`Task::queue`] waited for it (told before the samples that arrived
    /// after them, and once at its end; the runtime also prints the total).
    fn on_dropped(&mut self, total: u64) {
        let _ = total;
    }

    /// For a task that [wakes on input](Task::wakes_on_input): how long
    /// (fleet s) samples may gather before it is handed them all at once
    /// (0: each as soon as it arrives). A recorder of thousands of samples
    /// a second wakes once per batch, not once per sample.
    fn batch(&self) -> f64 {
        0.0
    }

    /// How it lingers after a stop request, taking what still arrives
    /// before its [last words](Task::stop) ([`Linger`]; `None`, the default:
    /// it stops at once). For a task that takes the others' last words (a
    /// recorder, a robot's base); never for a robot, which commands zero
    /// before anything else.
    fn linger(&self) -> Option<Linger> {
        None
    }

    /// Its clock started (reading 0) at UNIX ns `unix_ns`.
    fn started(&mut self, unix_ns: u64) {
        let _ = unix_ns;
    }

    /// Takes a sample that arrived through input `input`.
    fn on_input(&mut self, input: usize, sample: &Sample<'_>) -> Result<(), FleetError>;

    /// When it next wants a tick, on its clock (s); `-∞`: at once.
    fn next_wake(&self) -> f64;

    /// Runs at time `now` (its clock, s): at or after [`Task::next_wake`],
    /// or earlier (it decides what is due).
    fn tick(&mut self, now: f64, out: &mut dyn Outputs) -> Result<Flow, FleetError>;

    /// The task is stopping (done, a stop request, or an error): its last
    /// words, outputs still open.
    fn stop(&mut self, out: &mut dyn Outputs) -> Result<(), FleetError> {
        let _ = out;
        Ok(())
    }

    /// What it reports, once stopped (and, if it [wakes on
    /// input](Task::wakes_on_input), handed what arrived until its inputs
    /// closed).
    fn report(self) -> Result<Self::Report, FleetError>;
}
