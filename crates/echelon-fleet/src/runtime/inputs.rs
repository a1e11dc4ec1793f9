//! What arrives: a sample copied out of Zenoh's receive buffer into a
//! recycled buffer ([`Arrival`], [`Spares`]), queued for the task with
//! counted drops ([`Queue`]), and the Zenoh worker a subscription's
//! callback runs on ([`Worker`]).

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, OnceLock, mpsc};
use std::time::Instant;

use crate::latency;

/// A sample as a subscription hands it over: its key, payload and
/// attachment copied out of Zenoh's receive buffer (which goes back to
/// Zenoh's pool at once: holding it would make Zenoh allocate and zero a
/// new 64 KiB buffer for its next read) into one buffer of [`Spares`].
pub(super) struct Arrival {
    pub(super) input: usize,
    pub(super) at: Instant,
    pub(super) unix_ns: u64,
    pub(super) delay: Option<i64>,
    /// Key, then payload, then attachment.
    buf: Vec<u8>,
    /// Where the key ends in `buf`.
    key_end: usize,
    /// Where the payload ends in `buf`.
    payload_end: usize,
    attachment: bool,
}

impl Arrival {
    pub(super) fn key(&self) -> &str {
        std::str::from_utf8(&self.buf[..self.key_end]).unwrap_or("")
    }

    pub(super) fn payload(&self) -> &[u8] {
        &self.buf[self.key_end..self.payload_end]
    }

    pub(super) fn attachment(&self) -> Option<&[u8]> {
        self.attachment.then(|| &self.buf[self.payload_end..])
    }
}

/// Buffers of arrivals taken, handed back to the subscriptions' callbacks:
/// no allocation per sample once a few are in use.
#[derive(Debug, Clone, Default)]
pub(super) struct Spares(Arc<Mutex<Vec<Vec<u8>>>>);

impl Spares {
    /// Spares kept at most.
    const KEEP: usize = 64;

    /// `sample` copied into a spare buffer (a new one if none is left).
    pub(super) fn arrival(&self, input: usize, sample: &zenoh::sample::Sample) -> Arrival {
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
    pub(super) fn recycle(&self, a: Arrival) {
        if let Ok(mut v) = self.0.lock()
            && v.len() < Self::KEEP
        {
            v.push(a.buf);
        }
    }
}

/// Samples that arrived and wait for the task, at most (its
/// [`Task::queue`](super::Task::queue)); one more is dropped and counted,
/// never blocking Zenoh's receiving thread.
#[derive(Debug)]
pub(super) struct Queue<T> {
    tx: mpsc::SyncSender<T>,
    pub(super) dropped: Arc<AtomicU64>,
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
    pub(super) fn new(capacity: usize) -> (Queue<T>, mpsc::Receiver<T>) {
        let (tx, rx) = mpsc::sync_channel(capacity.max(1));
        let q = Queue {
            tx,
            dropped: Arc::default(),
        };
        (q, rx)
    }

    /// Queues `item`; if the queue is full, drops it and counts it (at
    /// once: never waits).
    pub(super) fn offer(&self, item: T) {
        if let Err(mpsc::TrySendError::Full(_)) = self.tx.try_send(item) {
            self.dropped.fetch_add(1, Ordering::Relaxed);
        }
    }
}

/// The thread of Zenoh's runtime that runs the subscriptions' callbacks
/// (one worker, [`crate::net::CLIENT_RUNTIME`]): noted by the first
/// callback that runs on it, so that a task's ticks can run there too.
#[derive(Debug, Clone, Default)]
pub(super) struct Worker(Arc<OnceLock<tokio::runtime::Handle>>);

impl Worker {
    /// Notes the runtime the calling thread runs (a callback from the
    /// network runs on Zenoh's; one delivered locally, on the publishing
    /// thread, runs on none and notes nothing).
    pub(super) fn note(&self) {
        if self.0.get().is_none()
            && let Ok(handle) = tokio::runtime::Handle::try_current()
        {
            let _ = self.0.set(handle);
        }
    }

    /// Zenoh's runtime, once a callback ran on it.
    pub(super) fn handle(&self) -> Option<&tokio::runtime::Handle> {
        self.0.get()
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
