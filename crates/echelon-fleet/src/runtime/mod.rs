//! The one runtime of the fleet's roles: what a role does is a [`Task`]
//! (sans-IO: inputs in, ticks at its next wake, outputs out, a typed report
//! at the end); [`run`] is the one Zenoh driver of every task, and
//! [`bus::Bus`] runs the same tasks in memory on a fake clock.
//!
//! [`run`]: open the session, declare the task's subscriptions, publishers
//! and liveliness tokens, wait for whom it waits for, then sleep until its
//! next wake (or, for a task that [wakes on input](Task::wakes_on_input),
//! until a sample arrives), hand it what arrived, tick it, publish what it
//! says; on a stop request, its end or an error: stop it, close the
//! session, take its report.

use std::collections::BTreeSet;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::mpsc;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use zenoh::Wait;
use zenoh::sample::SampleKind;

use crate::clock::FleetClock;
use crate::latency;
use crate::net::{self, NetOptions};
use crate::{FleetError, StopFlag};

pub mod bus;
mod task;

pub use task::{DEFAULT_QUEUE, Flow, Latching, Outputs, Sample, Task, WaitFor};

/// Longest sleep, real time, so that a stop request is seen.
pub const NAP: Duration = Duration::from_millis(20);
/// Longest wait for the answers to a task's latch query, real time.
pub const LATCH_QUERY_TIMEOUT: Duration = Duration::from_secs(1);

/// A sample as a subscription hands it over: its key, payload and
/// attachment copied out of Zenoh's receive buffer (which goes back to
/// Zenoh's pool at once: holding it would make Zenoh allocate and zero a
/// new 64 KiB buffer for its next read) into one buffer of [`Spares`].
struct Arrival {
    input: usize,
    at: Instant,
    unix_ns: u64,
    delay: Option<i64>,
    /// Key, then payload, then attachment.
    buf: Vec<u8>,
    /// Where the key ends in `buf`.
    key_end: usize,
    /// Where the payload ends in `buf`.
    payload_end: usize,
    attachment: bool,
}

impl Arrival {
    fn key(&self) -> &str {
        std::str::from_utf8(&self.buf[..self.key_end]).unwrap_or("")
    }
}

/// Buffers of arrivals taken, handed back to the subscriptions' callbacks:
/// no allocation per sample once a few are in use.
#[derive(Debug, Clone, Default)]
struct Spares(Arc<Mutex<Vec<Vec<u8>>>>);

impl Spares {
    /// Spares kept at most.
    const KEEP: usize = 64;

    /// `sample` copied into a spare buffer (a new one if none is left).
    fn arrival(&self, input: usize, sample: &zenoh::sample::Sample) -> Arrival {
        let unix_ns = crate::unix_nanos();
        let at = Instant::now();
        let mut buf = self
            .0
            .lock()
            .ok()
            .and_then(|mut v| v.pop())
            .unwrap_or_default();
        buf.clear();
        buf.extend_from_slice(sample.key_expr().as_str().as_bytes());
        let key_end = buf.len();
        for slice in sample.payload().slices() {
            buf.extend_from_slice(slice);
        }
        let payload_end = buf.len();
        if let Some(a) = sample.attachment() {
            for slice in a.slices() {
                buf.extend_from_slice(slice);
            }
        }
        Arrival {
            input,
            at,
            unix_ns,
            delay: latency::delay_ns(sample.timestamp(), unix_ns),
            buf,
            key_end,
            payload_end,
            attachment: sample.attachment().is_some(),
        }
    }

    /// Takes back the buffer of `a`, taken.
    fn recycle(&self, a: Arrival) {
        if let Ok(mut v) = self.0.lock()
            && v.len() < Self::KEEP
        {
            v.push(a.buf);
        }
    }
}

/// Samples that arrived and wait for the task, at most (its
/// [`Task::queue`]); one more is dropped and counted, never blocking
/// Zenoh's receiving thread.
#[derive(Debug)]
struct Queue<T> {
    tx: mpsc::SyncSender<T>,
    dropped: Arc<AtomicU64>,
}

impl<T> Clone for Queue<T> {
    fn clone(&self) -> Self {
        Queue {
            tx: self.tx.clone(),
            dropped: self.dropped.clone(),
        }
    }
}

impl<T> Queue<T> {
    /// A queue of `capacity` (at least 1), and its receiving end.
    fn new(capacity: usize) -> (Queue<T>, mpsc::Receiver<T>) {
        let (tx, rx) = mpsc::sync_channel(capacity.max(1));
        let q = Queue {
            tx,
            dropped: Arc::default(),
        };
        (q, rx)
    }

    /// Queues `item`; if the queue is full, drops it and counts it (at
    /// once: never waits).
    fn offer(&self, item: T) {
        if let Err(mpsc::TrySendError::Full(_)) = self.tx.try_send(item) {
            self.dropped.fetch_add(1, Ordering::Relaxed);
        }
    }
}

/// The Zenoh side of [`Outputs`].
struct ZenohOutputs<'a> {
    session: &'a zenoh::Session,
    publishers: Vec<zenoh::pubsub::Publisher<'a>>,
}

impl Outputs for ZenohOutputs<'_> {
    fn send(
        &mut self,
        output: usize,
        payload: &[u8],
        attachment: Option<&[u8]>,
    ) -> Result<(), FleetError> {
        let publisher = self.publisher(output)?;
        match attachment {
            None => net::publish(self.session, publisher, payload),
            Some(attachment) => publisher
                .put(payload.to_vec())
                .attachment(attachment.to_vec())
                .wait()
                .map_err(|e| FleetError::Zenoh(format!("publishing: {e}"))),
        }
    }

    fn put(&mut self, key: &str, payload: &[u8]) {
        net::put_stamped(self.session, key, payload.to_vec());
    }
}

impl<'a> ZenohOutputs<'a> {
    fn publisher(&self, output: usize) -> Result<&zenoh::pubsub::Publisher<'a>, FleetError> {
        self.publishers
            .get(output)
            .ok_or_else(|| FleetError::Zenoh(format!("no output {output}")))
    }
}

/// Runs `task` on a session opened with `net` until it stops or `stop` is
/// raised, and takes its report; `clock` is restarted (reading 0) when the
/// task starts.
pub fn run<T: Task>(
    task: T,
    net: &NetOptions,
    clock: FleetClock,
    stop: &StopFlag,
) -> Result<T::Report, FleetError> {
    run_on(|_| Ok((task, ())), net, clock, stop)?.report()
}

/// [`run`] for a task built on the session (`build` may also declare what
/// the task needs besides its inputs, outputs and tokens, e.g. a ROS 2
/// node's liveliness tokens, and hand it back as `G`, kept until the
/// session closes); returns the task stopped, its report not taken.
pub fn run_on<T: Task, G>(
    build: impl FnOnce(&zenoh::Session) -> Result<(T, G), FleetError>,
    net: &NetOptions,
    clock: FleetClock,
    stop: &StopFlag,
) -> Result<T, FleetError> {
    run_split(
        |fleet, _| build(fleet).map(|(task, guard)| (task, guard, Vec::new())),
        net,
        None,
        clock,
        stop,
    )
}

/// A second Zenoh network a task also talks to, kept apart from the
/// fleet's: a real robot's own (its `rmw_zenohd` or bridge).
#[derive(Debug, Clone)]
pub struct Device<'a> {
    /// How its session is opened.
    pub net: &'a NetOptions,
    /// What it is, for errors (`agent 2's robot at tcp/192.168.1.22:7447`).
    pub name: String,
    /// Wait this long (real time) for a first sample on the task's inputs
    /// from the device before declaring the task's liveliness tokens (before
    /// joining the fleet); `None`: do not wait.
    pub first_sample: Option<Duration>,
}

/// [`run_on`] with a second session, opened with `device` (none: the fleet's
/// session serves as both): `build` declares on either (fleet, device) and
/// names which of the task's inputs (keys as [`Task::inputs`] gives them)
/// are subscribed to on the device's session; every other input, output
/// and token is the fleet's. Nothing crosses from one network to the other.
pub fn run_split<T: Task, G>(
    build: impl FnOnce(&zenoh::Session, &zenoh::Session) -> Result<(T, G, Vec<String>), FleetError>,
    net: &NetOptions,
    device: Option<Device<'_>>,
    mut clock: FleetClock,
    stop: &StopFlag,
) -> Result<T, FleetError> {
    let session = net::open(net)?;
    let device_session = match &device {
        Some(d) => Some(
            net::open(d.net).map_err(|e| FleetError::Zenoh(format!("reaching {}: {e}", d.name)))?,
        ),
        None => None,
    };
    let dev = device_session.as_ref().unwrap_or(&session);
    let (mut task, guard, device_inputs) = build(&session, dev)?;
    let (queue, rx) = Queue::<Arrival>::new(task.queue());
    let dropped = queue.dropped.clone();
    let spares = Spares::default();
    let mut subscribers = Vec::new();
    let mut from_device = Vec::new();
    for (input, key) in task.inputs().into_iter().enumerate() {
        let queue = queue.clone();
        let spares = spares.clone();
        let on = if device_inputs.contains(&key) {
            from_device.push(input);
            dev
        } else {
            &session
        };
        let sub = on
            .declare_subscriber(&key)
            .callback(move |sample| queue.offer(spares.arrival(input, &sample)))
            .wait()
            .map_err(|e| FleetError::Zenoh(format!("subscribing to {key}: {e}")))?;
        subscribers.push(sub);
    }
    drop(queue);
    // Samples that arrived before the clock started, handed once it has.
    let mut early = Vec::new();
    if let Some(d) = &device
        && let Some(timeout) = d.first_sample
        && !from_device.is_empty()
    {
        let started = Instant::now();
        loop {
            if stop.is_raised() {
                break;
            }
            if started.elapsed() > timeout {
                return Err(FleetError::Config(format!(
                    "nothing arrived from {} within {:.0} s (is its driver running, and are the namespace, domain and key scheme right?)",
                    d.name,
                    timeout.as_secs_f64()
                )));
            }
            match rx.recv_timeout(NAP) {
                Ok(a) => {
                    let first = from_device.contains(&a.input);
                    early.push(a);
                    if first {
                        break;
                    }
                }
                Err(mpsc::RecvTimeoutError::Timeout) => {}
                Err(mpsc::RecvTimeoutError::Disconnected) => break,
            }
        }
    }
    let mut publishers = Vec::new();
    for key in task.outputs() {
        publishers.push(
            session
                .declare_publisher(key.clone())
                .wait()
                .map_err(|e| FleetError::Zenoh(format!("declaring {key}: {e}")))?,
        );
    }
    let mut tokens = Vec::new();
    for key in task.tokens() {
        tokens.push(
            session
                .liveliness()
                .declare_token(key)
                .wait()
                .map_err(|e| FleetError::Zenoh(format!("liveliness: {e}")))?,
        );
    }
    // The latch: answer queries with what the task says after each call;
    // ask once (after `wait_for`, so the awaited are asked too).
    let latching = task.latching();
    let answer: Arc<Mutex<Option<Vec<u8>>>> = Arc::new(Mutex::new(task.latched()));
    let _queryable = match &latching {
        Some(l) => Some(declare_latch(&session, &l.answer_on, answer.clone())?),
        None => None,
    };
    if let Some(w) = task.wait_for() {
        wait_for(&session, &w, stop)?;
    }
    let heard = match &latching {
        Some(l) => ask_latches(&session, l)?,
        None => Vec::new(),
    };
    clock.sync(0.0, Instant::now());
    task.started(crate::unix_nanos());
    let latch_input = task.inputs().len();
    for (key, payload) in &heard {
        task.on_input(
            latch_input,
            &Sample {
                key,
                payload,
                attachment: None,
                at: clock.now(),
                unix_ns: crate::unix_nanos(),
                delay: None,
            },
        )?;
    }
    let update = |task: &T| {
        if latching.is_some()
            && let Ok(mut a) = answer.lock()
        {
            *a = task.latched();
        }
    };
    update(&task);

    let mut out = ZenohOutputs {
        session: &session,
        publishers,
    };
    // Drops are handed to the task (as a running total) before what
    // arrived after them.
    let mut told = 0;
    let mut hand = |task: &mut T, a: Arrival| {
        let total = dropped.load(Ordering::Relaxed);
        if total != told {
            told = total;
            task.on_dropped(total);
        }
        let handed = task.on_input(
            a.input,
            &Sample {
                key: a.key(),
                payload: &a.buf[a.key_end..a.payload_end],
                attachment: a.attachment.then(|| &a.buf[a.payload_end..]),
                at: clock.at(a.at),
                unix_ns: a.unix_ns,
                delay: a.delay,
            },
        );
        spares.recycle(a);
        handed
    };
    let reactive = task.wakes_on_input();
    let batch = task.batch();
    let ran: Result<(), FleetError> = (|| {
        for a in early.drain(..) {
            hand(&mut task, a)?;
        }
        while !stop.is_raised() {
            if reactive && batch > 0.0 {
                // Let a batch gather (no wake-up per sample), take it all.
                clock.sleep_until(task.next_wake().min(clock.now() + batch), NAP);
                while let Ok(a) = rx.try_recv() {
                    hand(&mut task, a)?;
                }
                update(&task);
                if clock.now() < task.next_wake() {
                    continue;
                }
            } else if reactive {
                let left = (task.next_wake() - clock.now()).max(0.0);
                match rx.recv_timeout(clock.real(left).min(NAP)) {
                    Ok(a) => {
                        hand(&mut task, a)?;
                        update(&task);
                        continue;
                    }
                    Err(mpsc::RecvTimeoutError::Timeout) => {}
                    Err(mpsc::RecvTimeoutError::Disconnected) => return Ok(()),
                }
            } else {
                clock.sleep_until(task.next_wake(), NAP);
            }
            while let Ok(a) = rx.try_recv() {
                hand(&mut task, a)?;
            }
            let flow = task.tick(clock.now(), &mut out)?;
            update(&task);
            if flow == Flow::Stop {
                return Ok(());
            }
        }
        Ok(())
    })();
    let stopped = task.stop(&mut out);
    drop(out);
    drop(tokens);
    drop(guard);
    for sub in subscribers {
        let _ = sub.undeclare().wait();
    }
    let _ = session.close().wait();
    if let Some(d) = device_session {
        let _ = d.close().wait();
    }
    ran?;
    stopped?;
    if reactive {
        // What had arrived before the inputs closed.
        while let Ok(a) = rx.try_recv() {
            hand(&mut task, a)?;
        }
    }
    let total = dropped.load(Ordering::Relaxed);
    if total > 0 {
        task.on_dropped(total);
        eprintln!(
            "{total} samples dropped: more than {} waited for the task at once",
            task.queue()
        );
    }
    Ok(task)
}

/// Declares the queryable answering on `key` with what `answer` holds.
fn declare_latch(
    session: &zenoh::Session,
    key: &str,
    answer: Arc<Mutex<Option<Vec<u8>>>>,
) -> Result<zenoh::query::Queryable<()>, FleetError> {
    let reply_key = key.to_owned();
    session
        .declare_queryable(key)
        .callback(move |q| {
            let payload = answer.lock().ok().and_then(|a| a.clone());
            if let Some(p) = payload {
                let _ = q.reply(reply_key.clone(), p).wait();
            }
        })
        .wait()
        .map_err(|e| FleetError::Zenoh(format!("declaring the latch {key}: {e}")))
}

/// Asks every latch of `l.ask` (at most [`LATCH_QUERY_TIMEOUT`]): the
/// answers but the asker's own, `(key, payload)`.
fn ask_latches(
    session: &zenoh::Session,
    l: &Latching,
) -> Result<Vec<(String, Vec<u8>)>, FleetError> {
    let mut heard = query_all(session, &l.ask, LATCH_QUERY_TIMEOUT)?;
    heard.retain(|(key, _)| *key != l.answer_on);
    Ok(heard)
}

/// Every queryable's answers to a query on `ask` within `timeout`, `(key,
/// payload)`, unconsolidated.
pub fn query_all(
    session: &zenoh::Session,
    ask: &str,
    timeout: Duration,
) -> Result<Vec<(String, Vec<u8>)>, FleetError> {
    let replies = session
        .get(ask)
        .target(zenoh::query::QueryTarget::All)
        .consolidation(zenoh::query::ConsolidationMode::None)
        .timeout(timeout)
        .wait()
        .map_err(|e| FleetError::Zenoh(format!("asking {ask}: {e}")))?;
    let mut heard = Vec::new();
    while let Ok(reply) = replies.recv() {
        if let Ok(s) = reply.result() {
            heard.push((
                s.key_expr().as_str().to_owned(),
                s.payload().to_bytes().into_owned(),
            ));
        }
    }
    Ok(heard)
}

/// Waits until every name of `w` has a liveliness token under
/// `echelon/<fleet>/alive/`, or its timeout passes (or `stop` is raised).
fn wait_for(session: &zenoh::Session, w: &WaitFor, stop: &StopFlag) -> Result<(), FleetError> {
    if w.names.is_empty() {
        return Ok(());
    }
    let seen: Arc<Mutex<BTreeSet<String>>> = Arc::default();
    let sink = seen.clone();
    let prefix = w.keys.alive("");
    let _sub = session
        .liveliness()
        .declare_subscriber(w.keys.alive("**"))
        .history(true)
        .callback(move |s| {
            if s.kind() == SampleKind::Put
                && let Some(name) = s.key_expr().as_str().strip_prefix(&prefix)
                && let Ok(mut set) = sink.lock()
            {
                set.insert(name.to_owned());
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
            w.names
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
        if started.elapsed() > w.timeout {
            return Err(FleetError::Config(format!(
                "waited {:.0} s for {} to join the fleet",
                w.timeout.as_secs_f64(),
                missing.join(", ")
            )));
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        /// A full queue drops what comes (at once, from other threads
        /// too) and counts it: what is taken plus what is dropped is what
        /// was offered, and what is taken is the first `capacity` in order.
        #[test]
        fn a_full_queue_drops_and_counts(capacity in 1usize..64, offered in 0usize..300) {
            let (q, rx) = Queue::<usize>::new(capacity);
            let sender = q.clone();
            // From another thread, as Zenoh's: it must never block.
            std::thread::spawn(move || {
                for i in 0..offered {
                    sender.offer(i);
                }
            })
            .join()
            .unwrap();
            let taken: Vec<usize> = rx.try_iter().collect();
            let dropped = q.dropped.load(Ordering::Relaxed) as usize;
            prop_assert_eq!(taken.len(), offered.min(capacity));
            prop_assert_eq!(taken.len() + dropped, offered);
            prop_assert!(taken.iter().copied().eq(0..taken.len()));
            // Room again once taken.
            q.offer(7);
            prop_assert_eq!(rx.try_recv().ok(), Some(7));
        }
    }
}
