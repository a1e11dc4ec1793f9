//! An in-memory bus running [`Task`]s on one fake clock: what the Zenoh
//! runtime does, deterministically, without a network or a sleep (tests,
//! benches).
//!
//! Every task has a start (bus time at which its clock reads 0). The bus
//! goes from event to event: deliveries due (in the order they were sent),
//! then the ticks due (in the order the tasks were added), each followed by
//! the deliveries it made due (what it sent without latency reaches the
//! tasks that tick after it at the same instant). A publication
//! reaches every input whose key expression includes its key, the sender's
//! own included (as on Zenoh), after the [link](Bus::link)'s latency, or
//! never if the link drops it.

use std::any::Any;
use std::collections::BTreeMap;

use zenoh::key_expr::keyexpr;

use crate::FleetError;

use super::{Flow, Latching, Outgoing, Outputs, Sample, Task};

/// A task's number on the bus.
pub type TaskId = usize;

/// The sender of what [`Bus::put`] puts (no task).
pub const OUTSIDE: TaskId = usize::MAX;

/// One publication, as the bus logged it.
#[derive(Debug, Clone, PartialEq)]
pub struct Published {
    /// Bus time it was sent.
    pub t: f64,
    /// Its sender.
    pub from: TaskId,
    /// Its key.
    pub key: String,
    /// Its payload.
    pub payload: Vec<u8>,
}

/// Latency of a publication `(sender, key, bus time)`: `Some(s)`, or `None`
/// to drop it.
pub type Link = Box<dyn FnMut(TaskId, &str, f64) -> Option<f64>>;

/// A [`Task`] with its type and report erased.
trait Node: Any {
    fn inputs(&self) -> Vec<String>;
    fn outputs(&self) -> Vec<String>;
    fn on_input(&mut self, input: usize, sample: &Sample<'_>) -> Result<(), FleetError>;
    fn next_wake(&self) -> f64;
    fn tick(&mut self, now: f64, out: &mut dyn Outputs) -> Result<Flow, FleetError>;
    fn stop(&mut self, out: &mut dyn Outputs) -> Result<(), FleetError>;
    fn started(&mut self);
    fn latching(&self) -> Option<Latching>;
    fn latched(&self, i: usize) -> Option<Vec<u8>>;
    fn as_any(&self) -> &dyn Any;
    fn as_any_mut(&mut self) -> &mut dyn Any;
}

impl<T: Task + 'static> Node for T {
    fn inputs(&self) -> Vec<String> {
        Task::inputs(self)
    }
    fn outputs(&self) -> Vec<String> {
        Task::outputs(self)
    }
    fn on_input(&mut self, input: usize, sample: &Sample<'_>) -> Result<(), FleetError> {
        Task::on_input(self, input, sample)
    }
    fn next_wake(&self) -> f64 {
        Task::next_wake(self)
    }
    fn tick(&mut self, now: f64, out: &mut dyn Outputs) -> Result<Flow, FleetError> {
        Task::tick(self, now, out)
    }
    fn stop(&mut self, out: &mut dyn Outputs) -> Result<(), FleetError> {
        Task::stop(self, out)
    }
    fn started(&mut self) {
        Task::started(self, 0);
    }
    fn latching(&self) -> Option<Latching> {
        Task::latching(self)
    }
    fn latched(&self, i: usize) -> Option<Vec<u8>> {
        Task::latched(self, i)
    }
    fn as_any(&self) -> &dyn Any {
        self
    }
    fn as_any_mut(&mut self) -> &mut dyn Any {
        self
    }
}

struct Entry {
    node: Box<dyn Node>,
    start: f64,
    inputs: Vec<String>,
    outputs: Vec<String>,
    running: bool,
    error: Option<FleetError>,
}

impl Entry {
    /// `task`, started, its clock reading 0 at bus time `start`.
    fn new<T: Task + 'static>(task: T, start: f64) -> Entry {
        let mut node: Box<dyn Node> = Box::new(task);
        node.started();
        Entry {
            inputs: node.inputs(),
            outputs: node.outputs(),
            node,
            start,
            running: true,
            error: None,
        }
    }
}

/// A message on its way: `(arrival, sequence)` orders deliveries.
struct Pending {
    from: TaskId,
    key: String,
    payload: Vec<u8>,
    attachment: Option<Vec<u8>>,
    sent: f64,
}

/// What a task sent during one call, before the bus routes it.
#[derive(Default)]
struct Sent {
    outputs: Vec<String>,
    messages: Vec<(String, Vec<u8>, Option<Vec<u8>>)>,
}

impl Outputs for Sent {
    fn send(&mut self, m: Outgoing<'_>) -> Result<(), FleetError> {
        let key = self.key(m.output)?;
        self.messages
            .push((key, m.payload.to_vec(), m.attachment.map(<[u8]>::to_vec)));
        Ok(())
    }
    fn put(&mut self, key: &str, payload: &[u8]) {
        self.messages.push((key.to_owned(), payload.to_vec(), None));
    }
}

impl Sent {
    fn key(&self, output: usize) -> Result<String, FleetError> {
        super::declared(&self.outputs, output).cloned()
    }
}

/// Tasks exchanging messages in memory on one fake clock.
pub struct Bus {
    now: f64,
    entries: Vec<Entry>,
    queue: BTreeMap<(OrderedTime, u64), Pending>,
    seq: u64,
    /// Every publication so far.
    pub log: Vec<Published>,
    /// Decides each publication's latency (default: none, delivered at once).
    pub link: Link,
}

/// A time that sorts (never NaN on the bus).
#[derive(Debug, Clone, Copy)]
struct OrderedTime(f64);

impl PartialEq for OrderedTime {
    fn eq(&self, other: &Self) -> bool {
        self.cmp(other).is_eq()
    }
}

impl Eq for OrderedTime {}

impl PartialOrd for OrderedTime {
    fn partial_cmp(&self, other: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(other))
    }
}

impl Ord for OrderedTime {
    fn cmp(&self, other: &Self) -> std::cmp::Ordering {
        self.0.total_cmp(&other.0)
    }
}

impl Default for Bus {
    fn default() -> Self {
        Bus::new()
    }
}

impl std::fmt::Debug for Bus {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Bus")
            .field("now", &self.now)
            .field("tasks", &self.entries.len())
            .field("pending", &self.queue.len())
            .finish()
    }
}

fn includes(expr: &str, key: &str) -> bool {
    match (keyexpr::new(expr), keyexpr::new(key)) {
        (Ok(e), Ok(k)) => e.includes(k),
        _ => false,
    }
}

impl Bus {
    /// An empty bus at time 0 with a perfect link.
    pub fn new() -> Bus {
        Bus {
            now: 0.0,
            entries: Vec::new(),
            queue: BTreeMap::new(),
            seq: 0,
            log: Vec::new(),
            link: Box::new(|_, _, _| Some(0.0)),
        }
    }

    /// Bus time now.
    pub fn now(&self) -> f64 {
        self.now
    }

    /// Adds `task`, its clock reading 0 at bus time `start`.
    pub fn add<T: Task + 'static>(&mut self, task: T, start: f64) -> TaskId {
        self.entries.push(Entry::new(task, start));
        let id = self.entries.len() - 1;
        self.ask_latches(id);
        id
    }

    /// Puts `task` in place of task `id` (a restarted process), its clock
    /// reading 0 at bus time `start`.
    pub fn replace<T: Task + 'static>(&mut self, id: TaskId, task: T, start: f64) {
        self.entries[id] = Entry::new(task, start);
        self.ask_latches(id);
    }

    /// Task `id`'s latch query, as the runtime makes it when the task
    /// starts: what every other running task's latch under its key
    /// expression answers now, handed over at once (no latency, no loss).
    fn ask_latches(&mut self, id: TaskId) {
        let Some(l) = self.entries[id].node.latching() else {
            return;
        };
        let answers: Vec<(String, Vec<u8>)> = self
            .entries
            .iter()
            .enumerate()
            .filter(|(j, e)| *j != id && e.running)
            .filter_map(|(_, e)| Some((e, e.node.latching()?)))
            .flat_map(|(e, theirs)| {
                let ask = &l.ask;
                (theirs.answer_on.into_iter().enumerate()).filter_map(move |(i, key)| {
                    let payload = e.node.latched(i)?;
                    includes(ask, &key).then_some((key, payload))
                })
            })
            .collect();
        let e = &mut self.entries[id];
        let input = e.inputs.len();
        let at = self.now - e.start;
        for (key, payload) in answers {
            let sample = Sample {
                key: &key,
                payload: &payload,
                attachment: None,
                at,
                unix_ns: (at.max(0.0) * 1e9) as u64,
                delay: None,
            };
            if let Err(err) = e.node.on_input(input, &sample) {
                e.running = false;
                e.error = Some(err);
                return;
            }
        }
    }

    /// Task `id`, as its type (`None`: another type).
    pub fn task<T: Task + 'static>(&self, id: TaskId) -> Option<&T> {
        self.entries.get(id)?.node.as_any().downcast_ref()
    }

    /// Task `id`, as its type, to change.
    pub fn task_mut<T: Task + 'static>(&mut self, id: TaskId) -> Option<&mut T> {
        self.entries.get_mut(id)?.node.as_any_mut().downcast_mut()
    }

    /// Whether task `id` still runs.
    pub fn is_running(&self, id: TaskId) -> bool {
        self.entries.get(id).is_some_and(|e| e.running)
    }

    /// The error task `id` stopped on, if any.
    pub fn error(&self, id: TaskId) -> Option<&FleetError> {
        self.entries.get(id)?.error.as_ref()
    }

    /// Removes task `id` from the bus and returns it (it is not stopped);
    /// the other tasks keep their numbers.
    pub fn take<T: Task + 'static>(&mut self, id: TaskId) -> Option<T> {
        let e = self.entries.get_mut(id)?;
        if !e.node.as_any().is::<T>() {
            return None;
        }
        let placeholder: Box<dyn Node> = Box::new(Idle);
        let node = std::mem::replace(&mut e.node, placeholder);
        e.running = false;
        e.inputs.clear();
        let any: Box<dyn Any> = node;
        any.downcast().ok().map(|b| *b)
    }

    /// Publications of task `id` on `key`, in order.
    pub fn published_by<'a>(
        &'a self,
        id: TaskId,
        key: &'a str,
    ) -> impl Iterator<Item = &'a Published> + 'a {
        self.log
            .iter()
            .filter(move |p| p.from == id && p.key == key)
    }

    /// Puts `payload` on `key` now from outside the tasks (e.g. an
    /// operator's command), sender [`OUTSIDE`], through the link.
    pub fn put(&mut self, key: &str, payload: &[u8]) {
        let sent = Sent {
            messages: vec![(key.to_owned(), payload.to_vec(), None)],
            ..Sent::default()
        };
        self.route(OUTSIDE, sent);
    }

    /// What task `id`'s latch answers now (`None`: it holds none, or says
    /// nothing).
    pub fn latched(&self, id: TaskId) -> Option<Vec<u8>> {
        self.entries.get(id)?.node.latched(0)
    }

    /// Stops task `id` as the runtime does (its last words are sent).
    pub fn stop(&mut self, id: TaskId) -> Result<(), FleetError> {
        let e = &mut self.entries[id];
        if !e.running {
            return Ok(());
        }
        e.running = false;
        let mut sent = Sent {
            outputs: e.outputs.clone(),
            ..Sent::default()
        };
        let r = e.node.stop(&mut sent);
        self.route(id, sent);
        r
    }

    fn route(&mut self, from: TaskId, sent: Sent) {
        for (key, payload, attachment) in sent.messages {
            self.log.push(Published {
                t: self.now,
                from,
                key: key.clone(),
                payload: payload.clone(),
            });
            if let Some(latency) = (self.link)(from, &key, self.now) {
                self.queue.insert(
                    (OrderedTime(self.now + latency.max(0.0)), self.seq),
                    Pending {
                        from,
                        key,
                        payload,
                        attachment,
                        sent: self.now,
                    },
                );
                self.seq += 1;
            }
        }
    }

    fn deliver(&mut self, at: f64, p: &Pending) {
        let _ = p.from;
        let _ = p.sent;
        for e in &mut self.entries {
            if !e.running {
                continue;
            }
            for (input, expr) in e.inputs.iter().enumerate() {
                if includes(expr, &p.key) {
                    let sample = Sample {
                        key: &p.key,
                        payload: &p.payload,
                        attachment: p.attachment.as_deref(),
                        at: at - e.start,
                        unix_ns: (at.max(0.0) * 1e9) as u64,
                        delay: Some(((at - p.sent) * 1e9).round() as i64),
                    };
                    if let Err(err) = e.node.on_input(input, &sample) {
                        e.error = Some(err);
                        e.running = false;
                        break;
                    }
                }
            }
        }
    }

    fn next_event(&self) -> f64 {
        let delivery = self.queue.keys().next().map_or(f64::INFINITY, |(t, _)| t.0);
        self.entries
            .iter()
            .filter(|e| e.running)
            .map(|e| e.start + e.node.next_wake())
            .fold(delivery, f64::min)
    }

    /// Runs every task until bus time `end` (included).
    pub fn run_until(&mut self, end: f64) {
        let mut stalled = false;
        loop {
            let mut t = self.next_event().max(self.now);
            if stalled && t <= self.now {
                // A task woke and found nothing due (its wake rounded below
                // its due time): the next instant.
                t = self.now + 1e-12 * self.now.abs().max(1.0);
            }
            if t > end {
                self.now = self.now.max(end);
                return;
            }
            self.now = t;
            let mut progress = self.deliver_due();
            for id in 0..self.entries.len() {
                let e = &mut self.entries[id];
                if !e.running || e.start + e.node.next_wake() > t {
                    continue;
                }
                let before = e.node.next_wake();
                let mut sent = Sent {
                    outputs: e.outputs.clone(),
                    ..Sent::default()
                };
                let flow = e.node.tick(t - e.start, &mut sent);
                progress |= !sent.messages.is_empty() || e.node.next_wake() != before;
                self.route(id, sent);
                match flow {
                    Ok(Flow::Continue) => {}
                    Ok(Flow::Stop) => {
                        progress = true;
                        if let Err(err) = self.stop(id) {
                            self.entries[id].error = Some(err);
                        }
                    }
                    Err(err) => {
                        progress = true;
                        let _ = self.stop(id);
                        self.entries[id].error = Some(err);
                    }
                }
                // What it sent without latency reaches the next tasks now.
                progress |= self.deliver_due();
            }
            stalled = !progress;
        }
    }

    /// Delivers every message due by now, in order; whether there was any.
    fn deliver_due(&mut self) -> bool {
        let mut any = false;
        while let Some(entry) = self.queue.first_entry() {
            if entry.key().0.0 > self.now {
                break;
            }
            let ((at, _), p) = entry.remove_entry();
            self.deliver(at.0, &p);
            any = true;
        }
        any
    }
}

/// What is left on the bus where a task was taken.
struct Idle;

impl Task for Idle {
    type Report = ();
    fn inputs(&self) -> Vec<String> {
        Vec::new()
    }
    fn outputs(&self) -> Vec<String> {
        Vec::new()
    }
    fn on_input(&mut self, _: usize, _: &Sample<'_>) -> Result<(), FleetError> {
        Ok(())
    }
    fn next_wake(&self) -> f64 {
        f64::INFINITY
    }
    fn tick(&mut self, _: f64, _: &mut dyn Outputs) -> Result<Flow, FleetError> {
        Ok(Flow::Continue)
    }
    fn report(self) -> Result<(), FleetError> {
        Ok(())
    }
}

#[cfg(test)]
mod tests;
