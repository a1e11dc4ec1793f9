//! The one runtime of the fleet's roles: what a role does is a [`Task`]
//! (sans-IO: inputs in, ticks at its next wake, outputs out, a typed report
//! at the end); [`run`] is the one Zenoh driver of every task, and
//! [`bus::Bus`] runs the same tasks in memory on a fake clock.
//!
//! [`run`]: open the session, declare the task's subscriptions, publishers
//! and liveliness tokens, wait for whom it waits for, then sleep until its
//! next wake (or, for a task that [wakes on input](Task::wakes_on_input),
//! until a sample arrives), hand it what arrived, tick it, publish what it
//! says (on Zenoh's own thread once one of its samples arrived there: see
//! `drive.rs`); on a stop request, its end or an error: stop it (after a
//! stop request, a task that [lingers](Task::linger) first takes what still
//! arrives: `linger.rs`), make sure its last words reached the router or
//! peers (`net::flush`), close the session, take its report.
//!
//! By job: `inputs.rs` (what arrives, queued with counted drops),
//! `outputs.rs` (what it publishes), `presence.rs` (latches, liveliness),
//! `drive.rs` (where and when it ticks).

use std::sync::{Arc, Mutex, mpsc};
use std::time::{Duration, Instant};

use zenoh::Wait;

use crate::clock::FleetClock;
use crate::net::{self, NetOptions};
use crate::{FleetError, StopFlag};

pub mod bus;
mod drive;
mod inputs;
mod linger;
mod outputs;
mod presence;
mod task;

pub use drive::{COARSE, RETRY, STALL, WATCH};
pub use linger::{Linger, Lingered};
pub use presence::{Tokens, query_all};
pub use task::{DEFAULT_QUEUE, Flow, Latching, Outgoing, Outputs, Sample, Task, WaitFor};

use drive::{Answer, Engine};
use inputs::{Queue, Spares, Worker};
use outputs::ZenohOutputs;
use presence::{ask_latches, declare_latch, refuse_if_held, wait_for};
use task::declared;

/// Longest sleep, real time, so that a stop request is seen.
pub const NAP: Duration = Duration::from_millis(20);
/// How long an exclusive task waits for another holder of its token to
/// leave (a process restarted at once, whose old session the router has
/// not yet seen close) before it refuses, real time.
pub const EXCLUSIVE_WAIT: Duration = Duration::from_secs(3);
/// Longest wait for the answers to a task's latch query, real time.
pub const LATCH_QUERY_TIMEOUT: Duration = Duration::from_secs(1);

/// Runs `task` on a session opened with `net` until it stops or `stop` is
/// raised, and takes its report; `clock` is restarted (reading 0) when the
/// task starts.
pub fn run<T: Task + Send + 'static>(
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
pub fn run_on<T: Task + Send + 'static, G>(
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
pub fn run_split<T: Task + Send + 'static, G>(
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
    let (queue, rx) = Queue::new(task.queue());
    let dropped = queue.dropped.clone();
    let spares = Spares::default();
    let worker = Worker::default();
    let inputs = subscribe(
        &task,
        &session,
        dev,
        &device_inputs,
        &queue,
        &spares,
        &worker,
    )?;
    drop(queue);
    // Samples that arrived before the clock started, handed once it has.
    let early = first_samples(device.as_ref(), &inputs.from_device, &rx, stop)?;
    let publishers = declare_publishers(&session, &task)?;
    if task.exclusive() {
        refuse_if_held(&session, &task.tokens(), EXCLUSIVE_WAIT, stop)?;
    }
    let tokens = declare_tokens(&session, &task)?;
    // The latch: answer queries with what the task says after each call;
    // ask once (after `wait_for`, so the awaited are asked too).
    let latching = task.latching();
    let answers: Vec<Answer> = match &latching {
        Some(l) => (0..l.answer_on.len())
            .map(|i| Arc::new(Mutex::new(task.latched(i))))
            .collect(),
        None => Vec::new(),
    };
    let _queryables = match &latching {
        Some(l) => (l.answer_on.iter().zip(&answers))
            .map(|(key, answer)| declare_latch(&session, key, answer.clone()))
            .collect::<Result<Vec<_>, _>>()?,
        None => Vec::new(),
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
    hand_latched(&mut task, &heard, &clock)?;
    let mut engine = Engine {
        task,
        clock,
        rx,
        out: ZenohOutputs {
            session: session.clone(),
            publishers,
        },
        spares,
        dropped,
        told: 0,
        answers,
        answered: None,
        fine: 0,
        coarse: false,
    };
    engine.update();
    let ran = early.into_iter().try_for_each(|a| engine.hand(a));
    let (mut engine, ran) = match ran {
        Ok(()) => drive::drive(engine, &worker, stop),
        Err(e) => (engine, Err(e)),
    };
    // A stop request: first what still arrives (a task that lingers).
    let ran = match (ran, engine.task.linger()) {
        (Ok(()), Some(l)) if stop.is_raised() => engine.linger(l).map(|lingered| {
            if lingered.cut {
                eprintln!(
                    "inputs still arriving {:.1} s after the stop request: stopped anyway",
                    lingered.ended.as_secs_f64()
                );
            }
        }),
        (ran, _) => ran,
    };
    let stopped = engine.task.stop(&mut engine.out);
    close(
        &session,
        device_session,
        inputs,
        &mut engine.out,
        tokens,
        guard,
    );
    ran?;
    stopped?;
    finish(engine)
}

/// A task's subscriptions, each on the fleet's session or the device's.
struct Subscribed {
    /// Every input's subscriber, in the task's order.
    subscribers: Vec<zenoh::pubsub::Subscriber<()>>,
    /// The inputs subscribed to on the device's session.
    from_device: Vec<usize>,
    /// Keys each session (the fleet's, the device's) may query
    /// (`net::flush`): its first token, else its first subscription.
    flush_keys: (Option<String>, Option<String>),
}

/// Subscribes to every input of `task`, on `dev` those named in
/// `device_inputs`, on `session` the others; each sample offered to
/// `queue` (its buffer from `spares`), `worker` noting Zenoh's thread.
fn subscribe<T: Task>(
    task: &T,
    session: &zenoh::Session,
    dev: &zenoh::Session,
    device_inputs: &[String],
    queue: &Queue<inputs::Arrival>,
    spares: &Spares,
    worker: &Worker,
) -> Result<Subscribed, FleetError> {
    let mut subscribers = Vec::new();
    let mut from_device = Vec::new();
    let mut flush_keys = (task.tokens().into_iter().next(), None);
    for (input, key) in task.inputs().into_iter().enumerate() {
        let queue = queue.clone();
        let spares = spares.clone();
        let worker = worker.clone();
        let on = if device_inputs.contains(&key) {
            from_device.push(input);
            flush_keys.1.get_or_insert_with(|| key.clone());
            dev
        } else {
            flush_keys.0.get_or_insert_with(|| key.clone());
            session
        };
        let sub = on
            .declare_subscriber(&key)
            .callback(move |sample| {
                worker.note();
                queue.offer(spares.arrival(input, &sample));
            })
            .wait()
            .map_err(|e| FleetError::Zenoh(format!("subscribing to {key}: {e}")))?;
        subscribers.push(sub);
    }
    Ok(Subscribed {
        subscribers,
        from_device,
        flush_keys,
    })
}

/// With a device that asks for it ([`Device::first_sample`]) and inputs on
/// it: what arrives on `rx` until the first sample from the device (inputs
/// `from_device`), or a stop request; refused when none arrives in time.
fn first_samples(
    device: Option<&Device<'_>>,
    from_device: &[usize],
    rx: &mpsc::Receiver<inputs::Arrival>,
    stop: &StopFlag,
) -> Result<Vec<inputs::Arrival>, FleetError> {
    let mut early = Vec::new();
    if let Some(d) = device
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
    Ok(early)
}

/// A publisher on `session` for each of `task`'s outputs, in order.
fn declare_publishers<T: Task>(
    session: &zenoh::Session,
    task: &T,
) -> Result<Vec<zenoh::pubsub::Publisher<'static>>, FleetError> {
    let mut publishers = Vec::new();
    for key in task.outputs() {
        publishers.push(
            session
                .declare_publisher(key.clone())
                .wait()
                .map_err(|e| FleetError::Zenoh(format!("declaring {key}: {e}")))?,
        );
    }
    Ok(publishers)
}

/// `task`'s liveliness tokens, declared on `session`.
fn declare_tokens<T: Task>(
    session: &zenoh::Session,
    task: &T,
) -> Result<Vec<zenoh::liveliness::LivelinessToken>, FleetError> {
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
    Ok(tokens)
}

/// Hands `task` the latches `heard` (key, payload), on the input after its
/// own, stamped now on `clock`.
fn hand_latched<T: Task>(
    task: &mut T,
    heard: &[(String, Vec<u8>)],
    clock: &FleetClock,
) -> Result<(), FleetError> {
    let latch_input = task.inputs().len();
    for (key, payload) in heard {
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
    Ok(())
}

/// The task stopped: its last words on their way before the sessions
/// close (the fleet's, then the device's: a robot's final zero goes to its
/// robot), then its publishers, `tokens`, `guard` and subscriptions gone,
/// and both sessions closed.
fn close<G>(
    session: &zenoh::Session,
    device_session: Option<zenoh::Session>,
    inputs: Subscribed,
    out: &mut ZenohOutputs,
    tokens: Vec<zenoh::liveliness::LivelinessToken>,
    guard: G,
) {
    let sessions = [
        (Some(session), inputs.flush_keys.0),
        (device_session.as_ref(), inputs.flush_keys.1),
    ];
    for (s, key) in sessions {
        if let (Some(s), Some(key)) = (s, key)
            && let Err(e) = net::flush(s, &key, net::FLUSH_TIMEOUT)
        {
            eprintln!("{e}: its last messages may not have arrived");
        }
    }
    out.publishers.clear();
    drop(tokens);
    drop(guard);
    for sub in inputs.subscribers {
        let _ = sub.undeclare().wait();
    }
    let _ = session.close().wait();
    if let Some(d) = device_session {
        let _ = d.close().wait();
    }
}

/// The task's end, once its sessions are closed: what had arrived before
/// its inputs closed handed (a task that wakes on input), the samples
/// dropped told and said.
fn finish<T: Task>(mut engine: Engine<T>) -> Result<T, FleetError> {
    if engine.task.wakes_on_input() {
        // What had arrived before the inputs closed.
        engine.drain()?;
    }
    let total = engine.dropped.load(std::sync::atomic::Ordering::Relaxed);
    if total > 0 {
        engine.task.on_dropped(total);
        eprintln!(
            "{total} samples dropped: more than {} waited for the task at once",
            engine.task.queue()
        );
    }
    Ok(engine.task)
}

#[cfg(test)]
mod testing;
#[cfg(test)]
mod tests;
