//! A task's linger after a stop request ([`Task::linger`]): it keeps
//! taking what arrives until its inputs have been quiet for a while, bounded.
//!
//! Why: the processes whose last words it takes (a robot's final zero
//! `cmd_vel` for its base, the leader's last reference samples for the
//! collector) made sure, before they exited, that their router (in a mesh,
//! each peer) holds them (`net::flush`); from there they are on a live link
//! but may still be in flight (queued at the router, or in this process's
//! reception) when the stop request comes. A sample already in the task's
//! queue is taken at once; the quiet window covers the last hop.
//!
//! [`Task::linger`]: super::Task::linger

use std::time::Duration;

use crate::FleetError;

/// How a task lingers after a stop request: it takes what arrives until no
/// sample came for `quiet`, counted from the request or from the last
/// sample, and stops at `max` after the request whatever still arrives.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Linger {
    /// The quiet that ends it, real time.
    pub quiet: Duration,
    /// Its bound from the stop request, real time: a publisher that never
    /// stops cannot hold the task.
    pub max: Duration,
}

impl Linger {
    /// A fleet process that takes the others' last words (the collector, a
    /// simulated ROS 2 base): 150 ms of quiet, at most 5 s.
    pub const FLEET: Linger = Linger {
        quiet: Duration::from_millis(150),
        max: Duration::from_secs(5),
    };

    /// When it ends (time since the stop request), the last sample taken
    /// at `last` (since the request; `None`: none yet).
    pub fn end(&self, last: Option<Duration>) -> Duration {
        (last.unwrap_or(Duration::ZERO) + self.quiet).min(self.max)
    }
}

/// What a linger did.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Lingered {
    /// Samples taken.
    pub taken: u64,
    /// When it ended, since the stop request.
    pub ended: Duration,
    /// Whether it was cut at [`Linger::max`] with samples still arriving
    /// (the last one less than `quiet` before).
    pub cut: bool,
}

/// What waiting for one sample gave ([`linger`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Waited {
    /// One came, and the task took it.
    Took,
    /// None came in the time given.
    Quiet,
    /// The inputs closed: nothing more can come.
    Closed,
}

/// Lingers as `linger` says: `clock` reads the time since the stop
/// request; `take_next(wait)` waits at most `wait` for a sample and hands
/// it to the task.
pub(super) fn linger(
    linger: Linger,
    clock: impl Fn() -> Duration,
    mut take_next: impl FnMut(Duration) -> Result<Waited, FleetError>,
) -> Result<Lingered, FleetError> {
    let mut last = None;
    let mut taken = 0;
    loop {
        let now = clock();
        let end = linger.end(last);
        if now >= end {
            break;
        }
        match take_next(end - now)? {
            Waited::Took => {
                last = Some(clock());
                taken += 1;
            }
            Waited::Quiet => {}
            Waited::Closed => break,
        }
    }
    Ok(Lingered {
        taken,
        ended: clock(),
        cut: last.is_some_and(|t| t + linger.quiet > linger.max),
    })
}

#[cfg(test)]
mod tests {
    use std::cell::Cell;

    use proptest::prelude::*;

    use super::*;

    /// Lingers on a fake clock over samples arriving at `arrivals` (ms
    /// since the stop request, sorted): what it did and the arrivals taken.
    fn run(l: Linger, arrivals: &[u64]) -> (Lingered, Vec<u64>) {
        let now = Cell::new(Duration::ZERO);
        let mut pending = arrivals.iter().copied().peekable();
        let mut taken = Vec::new();
        let lingered = linger(
            l,
            || now.get(),
            |wait| {
                let until = now.get() + wait;
                match pending.peek() {
                    Some(&a) if Duration::from_millis(a) <= until => {
                        now.set(now.get().max(Duration::from_millis(a)));
                        pending.next();
                        taken.push(a);
                        Ok(Waited::Took)
                    }
                    _ => {
                        now.set(until);
                        Ok(Waited::Quiet)
                    }
                }
            },
        )
        .unwrap_or_else(|e| panic!("{e}"));
        (lingered, taken)
    }

    proptest! {
        /// Whatever arrives when: it ends at the first moment `quiet` has
        /// passed since the request and since the last sample, or at
        /// `max`; it took every sample that arrived until then, in order,
        /// and none after; it says when it was cut short.
        #[test]
        fn it_ends_at_the_first_quiet_or_at_its_bound(
            quiet in 1u64..400,
            max in 1u64..3000,
            gaps in proptest::collection::vec(0u64..600, 0..40),
        ) {
            let arrivals: Vec<u64> = gaps
                .iter()
                .scan(0, |t, g| {
                    *t += g;
                    Some(*t)
                })
                .collect();
            let l = Linger {
                quiet: Duration::from_millis(quiet),
                max: Duration::from_millis(max),
            };
            // The oracle: the window moves on with each sample inside it.
            let mut end = quiet;
            let mut last = None;
            for &a in &arrivals {
                if a > end.min(max) {
                    break;
                }
                end = a + quiet;
                last = Some(a);
            }
            let end = end.min(max);
            let (lingered, taken) = run(l, &arrivals);
            prop_assert_eq!(lingered.ended, Duration::from_millis(end));
            let expected: Vec<u64> = arrivals.iter().copied().filter(|&a| a <= end).collect();
            prop_assert_eq!(&taken, &expected);
            prop_assert_eq!(lingered.taken, taken.len() as u64);
            prop_assert!(lingered.ended <= l.max);
            prop_assert!(lingered.ended >= l.quiet.min(l.max));
            prop_assert_eq!(lingered.cut, last.is_some_and(|t| t + quiet > max));
            // No quiet of `quiet` before the end: else it would have ended there.
            let mut from = 0;
            for &a in &taken {
                prop_assert!(a - from <= quiet, "{} ms of quiet before {}", a - from, a);
                from = a;
            }
        }
    }

    /// Inputs that close end it at once: nothing more can come.
    #[test]
    fn closed_inputs_end_it() {
        let lingered = linger(Linger::FLEET, || Duration::ZERO, |_| Ok(Waited::Closed))
            .unwrap_or_else(|e| panic!("{e}"));
        assert_eq!((lingered.taken, lingered.cut), (0, false));
    }
}
