//! The Zenoh runtime with a real session on loopback: where a controller's
//! ticks run, and that they are never early and what they send arrives.

use std::thread::ThreadId;
use std::time::Duration;

use zenoh::Wait;

use super::*;
use crate::keys::Keys;
use crate::runtime::testing::{Periodic, Tick};
use crate::testing::serve_on_loopback;

const FLEET: &str = "probe";
const INPUT: &str = "echelon/probe/in";
const OUTPUT: &str = "echelon/probe/out";

/// A controller ticking every `period` fleet s `ticks` times when due
/// (each due tick logged with the thread it ran on and the samples handed
/// before it), publishing its tick count on [`OUTPUT`] and fed on
/// [`INPUT`]. The feeder's subscription is declared before its token, so
/// once the token is seen every state published reaches it.
fn probe_task(period: f64, ticks: usize) -> Periodic {
    let mut p = Periodic::new(period, ticks, INPUT, OUTPUT);
    p.wait_for = Some(WaitFor {
        keys: Keys::new(FLEET),
        names: vec!["feeder".to_owned()],
        timeout: Duration::from_secs(30),
    });
    p
}

/// Runs `probe` on a session listening on a free port while a second
/// session puts a sample on its input every `feed` (none: never) and
/// counts what it publishes; the probe stopped, the calling thread's id,
/// and the samples received from it.
fn run_probe(probe: Periodic, feed: Option<Duration>) -> (Periodic, ThreadId, usize) {
    let (endpoint, stop, runner) = serve_on_loopback(move |net, stop| {
        let probe = run_on(|_| Ok((probe, ())), net, FleetClock::new(1.0), stop);
        (probe, std::thread::current().id())
    });
    let feeder = net::open(&NetOptions {
        connect: vec![endpoint],
        ..NetOptions::default()
    })
    .unwrap_or_else(|e| panic!("{e}"));
    let received = feeder
        .declare_subscriber(OUTPUT)
        .wait()
        .unwrap_or_else(|e| panic!("{e}"));
    let _token = feeder
        .liveliness()
        .declare_token(Keys::new(FLEET).alive("feeder"))
        .wait()
        .unwrap_or_else(|e| panic!("{e}"));
    while !runner.is_finished() {
        match feed {
            Some(every) => {
                let _ = feeder.put(INPUT, vec![1u8]).wait();
                std::thread::sleep(every);
            }
            None => std::thread::sleep(Duration::from_millis(20)),
        }
    }
    let (probe, caller) = runner.join().unwrap_or_else(|_| panic!("the runner"));
    let probe = probe.unwrap_or_else(|e| panic!("{e}"));
    // What it published and is still on its way, then nothing more.
    let mut got = 0;
    while let Ok(Some(_)) = received.recv_timeout(Duration::from_millis(500)) {
        got += 1;
    }
    stop.raise();
    let _ = feeder.close().wait();
    (probe, caller, got)
}

/// A controller fed samples: once one arrived (Zenoh's thread known) its
/// ticks run on Zenoh's thread, not the calling one; no tick is early,
/// none is skipped, and every state it published arrives.
#[test]
fn a_controller_ticks_on_zenohs_thread_once_a_sample_arrived() {
    let ticks = 150;
    let (probe, caller, got) = run_probe(probe_task(0.01, ticks), Some(Duration::from_millis(5)));
    assert_eq!(probe.log.len(), ticks);
    for (i, &Tick { now, due, .. }) in probe.log.iter().enumerate() {
        assert!(now >= due, "tick {i} at {now} before its wake {due}");
        assert!((due - i as f64 * 0.01).abs() < 1e-9, "tick {i} due {due}");
    }
    let first_fed = probe
        .log
        .iter()
        .position(|tick| tick.heard > 0)
        .unwrap_or_else(|| panic!("no sample handed: {:?}", probe.log));
    // From the tick after the first sample on, on Zenoh's thread (back on
    // the caller only after a tick late by more than `STALL`, on a loaded
    // machine).
    let after = &probe.log[first_fed + 1..];
    assert!(
        after.first().is_some_and(|tick| tick.thread != caller),
        "{:?}",
        probe.log
    );
    assert_eq!(got, ticks);
}

/// Ticks closer than [`COARSE`] stay on the calling thread (Zenoh's timer
/// is too coarse for them), fed or not; and a controller that hears
/// nothing ticks there too.
#[test]
fn fine_ticks_and_an_unfed_controller_stay_on_the_calling_thread() {
    let coarse = COARSE.as_secs_f64();
    for (period, feed) in [(coarse / 4.0, Some(Duration::from_millis(1))), (0.01, None)] {
        let (probe, caller, got) = run_probe(probe_task(period, 100), feed);
        assert_eq!(probe.log.len(), 100);
        assert!(probe.log.iter().all(|tick| tick.now >= tick.due));
        assert!(
            probe.log.iter().all(|tick| tick.thread == caller),
            "period {period}: {:?}",
            probe.log
        );
        assert_eq!(got, 100);
    }
}
