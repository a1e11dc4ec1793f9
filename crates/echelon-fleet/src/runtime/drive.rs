//! Where a task's ticks run.
//!
//! A controller (a task that does not [wake on input](Task::wakes_on_input))
//! ticks on the thread of Zenoh's runtime once a subscription's callback
//! has run there ([`Worker`]): its timer is that runtime's, so a tick wakes
//! one thread, and what it publishes goes out from the same thread (Zenoh's
//! transmission task is scheduled there without waking another). Until
//! then, and for a task whose ticks come less than [`COARSE`] apart (real
//! time; Zenoh's timer has a resolution of 1 ms), the calling thread ticks
//! it, sleeping until its next wake. That thread watches meanwhile: a stop
//! request, the task's end, and a tick more than [`STALL`] late (Zenoh's
//! thread busy elsewhere, or the machine overloaded) take the task back to
//! it (for [`RETRY`]).
//!
//! A recorder (a task that wakes on input) runs on the calling thread.

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, mpsc};
use std::time::{Duration, Instant};

use crate::clock::FleetClock;
use crate::{FleetError, StopFlag};

use super::inputs::{Arrival, Spares, Worker};
use super::linger::Waited;
use super::outputs::ZenohOutputs;
use super::{Flow, Linger, Lingered, NAP, Sample, Task};

/// Ticks closer than this (real time) stay on the calling thread's precise
/// sleep.
pub const COARSE: Duration = Duration::from_millis(4);
/// A task is ticking finer than [`COARSE`] once this many ticks in a row
/// moved its next wake by less (one does not tell: a robot's next wake
/// jumps when it syncs its clock to its leader's).
const FINE_TICKS: u32 = 3;
/// How often the calling thread looks at a task ticked on Zenoh's thread.
pub const WATCH: Duration = Duration::from_millis(100);
/// A tick this late (real time) on Zenoh's thread takes the task back to
/// the calling thread (said on stderr), for [`RETRY`]: half a robot's link
/// timeout.
pub const STALL: Duration = Duration::from_millis(100);
/// How long the calling thread keeps a task it took back from a stalled
/// Zenoh thread, real time.
pub const RETRY: Duration = Duration::from_secs(1);

/// What one of a task's latch keys answers, shared with its queryable.
pub(super) type Answer = Arc<Mutex<Option<Vec<u8>>>>;

/// A task with what ticking it needs: its clock, its inputs' queue, its
/// outputs and latch.
pub(super) struct Engine<T> {
    pub(super) task: T,
    pub(super) clock: FleetClock,
    pub(super) rx: mpsc::Receiver<Arrival>,
    pub(super) out: ZenohOutputs,
    pub(super) spares: Spares,
    /// Samples dropped so far, the queue full.
    pub(super) dropped: Arc<AtomicU64>,
    /// Drops the task was told of.
    pub(super) told: u64,
    /// What its latch answers, one per key it answers on (none: it holds
    /// none).
    pub(super) answers: Vec<Answer>,
    /// The task's [`Task::latch_changes`] when `answer` was last set.
    pub(super) answered: Option<u64>,
    /// Ticks in a row that moved its next wake by less than [`COARSE`].
    pub(super) fine: u32,
    /// Whether the last tick that moved its next wake moved it by
    /// [`COARSE`] or more (none yet: `false`).
    pub(super) coarse: bool,
}

impl<T: Task> Engine<T> {
    /// Hands `a` to the task (its drops, if any, first), and takes its
    /// buffer back.
    pub(super) fn hand(&mut self, a: Arrival) -> Result<(), FleetError> {
        let total = self.dropped.load(Ordering::Relaxed);
        if total != self.told {
            self.told = total;
            self.task.on_dropped(total);
        }
        let handed = self.task.on_input(
            a.input,
            &Sample {
                key: a.key(),
                payload: a.payload(),
                attachment: a.attachment(),
                at: self.clock.at(a.at),
                unix_ns: a.unix_ns,
                delay: a.delay,
            },
        );
        self.spares.recycle(a);
        handed
    }

    /// Hands the task everything that waits for it.
    pub(super) fn drain(&mut self) -> Result<(), FleetError> {
        while let Ok(a) = self.rx.try_recv() {
            self.hand(a)?;
        }
        Ok(())
    }

    /// After a stop request: hands the task what still arrives until its
    /// inputs were quiet, as `l` says ([`super::linger`]).
    pub(super) fn linger(&mut self, l: Linger) -> Result<Lingered, FleetError> {
        let start = Instant::now();
        super::linger::linger(
            l,
            || start.elapsed(),
            |wait| match self.rx.recv_timeout(wait) {
                Ok(a) => self.hand(a).map(|()| Waited::Took),
                Err(mpsc::RecvTimeoutError::Timeout) => Ok(Waited::Quiet),
                Err(mpsc::RecvTimeoutError::Disconnected) => Ok(Waited::Closed),
            },
        )
    }

    /// Sets what its latch answers to what the task says now (encoded
    /// again only when [`Task::latch_changes`] moved, or is unknown).
    pub(super) fn update(&mut self) {
        let changes = self.task.latch_changes();
        if changes.is_some() && changes == self.answered {
            return;
        }
        for (i, answer) in self.answers.iter().enumerate() {
            if let Ok(mut a) = answer.lock() {
                *a = self.task.latched(i);
            }
        }
        self.answered = changes;
    }

    /// What waits, then a tick now.
    fn step(&mut self) -> Result<Flow, FleetError> {
        self.drain()?;
        let before = self.task.next_wake();
        let flow = self.task.tick(self.clock.now(), &mut self.out)?;
        let after = self.task.next_wake();
        if after > before {
            self.coarse = self.clock.real(after - before) >= COARSE;
            self.fine = if self.coarse { 0 } else { self.fine + 1 };
        }
        self.update();
        Ok(flow)
    }

    /// Whether its ticks come closer than [`COARSE`].
    fn is_fine(&self) -> bool {
        self.fine >= FINE_TICKS
    }

    /// Real time until the task's next wake (zero if it is due).
    fn left(&self) -> Duration {
        self.clock
            .real((self.task.next_wake() - self.clock.now()).max(0.0))
    }

    /// Real time the task's next wake is past (zero if it is not).
    fn late(&self) -> Duration {
        self.clock
            .real((self.clock.now() - self.task.next_wake()).max(0.0))
    }
}

/// Why Zenoh's thread gave the task back.
enum Back {
    /// The task stopped, or failed.
    Ended(Result<(), FleetError>),
    /// Its ticks came closer than [`COARSE`].
    Fine,
    /// Its tick was this late.
    Stalled(Duration),
    /// A stop request.
    Stop,
}

/// Runs `engine`'s task until it stops, fails, or `stop` is raised (see the
/// module's documentation for where); hands the engine back for the task's
/// last words.
pub(super) fn drive<T: Task + Send + 'static>(
    mut engine: Engine<T>,
    worker: &Worker,
    stop: &StopFlag,
) -> (Engine<T>, Result<(), FleetError>) {
    let reactive = engine.task.wakes_on_input();
    let batch = engine.task.batch();
    // When the task may go to Zenoh's thread (`None`: never).
    let mut hand_over = (!reactive).then(Instant::now);
    while !stop.is_raised() {
        if hand_over.is_some_and(|at| Instant::now() >= at)
            && let Some(handle) = worker.handle()
            && engine.coarse
        {
            let (back, e) = on_worker(engine, handle, stop);
            engine = e;
            match back {
                Back::Ended(ran) => return (engine, ran),
                Back::Stop => return (engine, Ok(())),
                Back::Fine => hand_over = None,
                Back::Stalled(late) => {
                    eprintln!(
                        "a tick {:.0} ms late on Zenoh's thread: ticking on the process's own thread for {} s",
                        late.as_secs_f64() * 1e3,
                        RETRY.as_secs_f64()
                    );
                    hand_over = Some(Instant::now() + RETRY);
                }
            }
            continue;
        }
        let ran = if reactive {
            on_input(&mut engine, batch)
        } else {
            engine.clock.sleep_until(engine.task.next_wake(), NAP);
            engine.step().map(Some)
        };
        match ran {
            Ok(Some(Flow::Stop)) => return (engine, Ok(())),
            Ok(_) => {}
            Err(e) => return (engine, Err(e)),
        }
    }
    (engine, Ok(()))
}

/// One wait of a recorder: for a batch (`batch` fleet s), or for one sample;
/// then a tick if it is due. `None`: no tick was due.
fn on_input<T: Task>(engine: &mut Engine<T>, batch: f64) -> Result<Option<Flow>, FleetError> {
    if batch > 0.0 {
        // Let a batch gather (no wake-up per sample), take it all.
        let clock = engine.clock;
        clock.sleep_until(engine.task.next_wake().min(clock.now() + batch), NAP);
        engine.drain()?;
        engine.update();
        if clock.now() < engine.task.next_wake() {
            return Ok(None);
        }
    } else {
        match engine.rx.recv_timeout(engine.left().min(NAP)) {
            Ok(a) => {
                engine.hand(a)?;
                engine.update();
                return Ok(None);
            }
            Err(mpsc::RecvTimeoutError::Timeout) => {}
            // The inputs closed: the task is done.
            Err(mpsc::RecvTimeoutError::Disconnected) => return Ok(Some(Flow::Stop)),
        }
    }
    engine.step().map(Some)
}

/// Ticks the task on Zenoh's thread (`handle`) while the calling thread
/// watches, until it comes back (and why).
fn on_worker<T: Task + Send + 'static>(
    engine: Engine<T>,
    handle: &tokio::runtime::Handle,
    stop: &StopFlag,
) -> (Back, Engine<T>) {
    let shared = Arc::new(Mutex::new(Some(engine)));
    let (tx, rx) = mpsc::channel();
    handle.spawn(ticker(shared.clone(), stop.clone(), tx));
    let back = loop {
        match rx.recv_timeout(WATCH) {
            Ok(back) => break back,
            // The ticker ended without a word: the task panicked there.
            Err(mpsc::RecvTimeoutError::Disconnected) => {
                break Back::Ended(Err(FleetError::Config(
                    "the task panicked on Zenoh's thread".into(),
                )));
            }
            Err(mpsc::RecvTimeoutError::Timeout) => {
                if stop.is_raised() {
                    break Back::Stop;
                }
                let late = shared
                    .lock()
                    .ok()
                    .and_then(|e| e.as_ref().map(Engine::late));
                match late {
                    Some(late) if late <= STALL => {}
                    Some(late) => break Back::Stalled(late),
                    None => break Back::Fine,
                }
            }
        }
    };
    // Taken back (even from a tick that panicked: its last words, zero
    // commanded, are still said): the ticker finds nothing at its next
    // wake and ends.
    let engine = shared
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
        .take();
    match engine {
        Some(engine) => (back, engine),
        None => unreachable!("only the calling thread takes the task"),
    }
}

/// The task's ticks on Zenoh's thread: sleep on its timer until the next
/// wake, tick; tells `back` why it stopped (the task is then left where it
/// is, for the calling thread to take).
async fn ticker<T: Task>(
    shared: Arc<Mutex<Option<Engine<T>>>>,
    stop: StopFlag,
    back: mpsc::Sender<Back>,
) {
    loop {
        let left = match shared.lock() {
            Ok(guard) => match guard.as_ref() {
                Some(engine) => engine.left(),
                None => return,
            },
            Err(_) => return,
        };
        if left.is_zero() {
            tokio::task::yield_now().await;
        } else {
            tokio::time::sleep_until((Instant::now() + left).into()).await;
        }
        let Ok(mut guard) = shared.lock() else { return };
        let Some(engine) = guard.as_mut() else { return };
        let why = if stop.is_raised() {
            Back::Stop
        } else {
            match engine.step() {
                Ok(Flow::Continue) if engine.is_fine() => Back::Fine,
                Ok(Flow::Continue) => continue,
                Ok(Flow::Stop) => Back::Ended(Ok(())),
                Err(e) => Back::Ended(Err(e)),
            }
        };
        let _ = back.send(why);
        return;
    }
}
