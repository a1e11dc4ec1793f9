//! The Zenoh runtime with a real session on loopback: where a controller's
//! ticks run, and that they are never early and what they send arrives.

use std::thread::ThreadId;
use std::time::Duration;

use zenoh::Wait;

use super::*;
use crate::keys::Keys;
use crate::up::free_ports;

const FLEET: &str = "probe";
const INPUT: &str = "echelon/probe/in";
const OUTPUT: &str = "echelon/probe/out";

/// A controller ticking every `period` fleet s until it has ticked `ticks`
/// times when due; it records each due tick (time, the wake it was due at,
/// the thread) and the samples it was handed, and publishes its tick count.
#[derive(Debug)]
struct Probe {
    period: f64,
    ticks: usize,
    next: f64,
    handed: usize,
    /// Samples handed before each due tick.
    log: Vec<(f64, f64, ThreadId, usize)>,
}

impl Probe {
    fn new(period: f64, ticks: usize) -> Probe {
        Probe {
            period,
            ticks,
            next: 0.0,
            handed: 0,
            log: Vec::new(),
        }
    }
}

impl Task for Probe {
    type Report = ();

    fn inputs(&self) -> Vec<String> {
        vec![INPUT.to_owned()]
    }

    fn outputs(&self) -> Vec<String> {
        vec![OUTPUT.to_owned()]
    }

    /// The feeder: its subscription is declared before its token, so once
    /// the token is seen every state published reaches it.
    fn wait_for(&self) -> Option<WaitFor> {
        Some(WaitFor {
            keys: Keys::new(FLEET),
            names: vec!["feeder".to_owned()],
            timeout: Duration::from_secs(30),
        })
    }

    fn on_input(&mut self, _input: usize, _sample: &Sample<'_>) -> Result<(), FleetError> {
        self.handed += 1;
        Ok(())
    }

    fn next_wake(&self) -> f64 {
        self.next
    }

    fn tick(&mut self, now: f64, out: &mut dyn Outputs) -> Result<Flow, FleetError> {
        if now < self.next {
            return Ok(Flow::Continue);
        }
        self.log
            .push((now, self.next, std::thread::current().id(), self.handed));
        out.publish(0, &(self.log.len() as u64).to_le_bytes())?;
        self.next += self.period;
        Ok(if self.log.len() >= self.ticks {
            Flow::Stop
        } else {
            Flow::Continue
        })
    }

    fn report(self) -> Result<(), FleetError> {
        Ok(())
    }
}

/// Runs `probe` on a session listening on a free port while a second
/// session puts a sample on its input every `feed` (none: never) and
/// counts what it publishes; the probe stopped, the calling thread's id,
/// and the samples received from it.
fn run_probe(probe: Probe, feed: Option<Duration>) -> (Probe, ThreadId, usize) {
    let port = free_ports(1).unwrap_or_else(|e| panic!("{e}"))[0];
    let endpoint = format!("tcp/127.0.0.1:{port}");
    let stop = StopFlag::new();
    let runner = {
        let (endpoint, stop) = (endpoint.clone(), stop.clone());
        std::thread::spawn(move || {
            let net = NetOptions {
                listen: vec![endpoint],
                ..NetOptions::default()
            };
            let probe = run_on(|_| Ok((probe, ())), &net, FleetClock::new(1.0), &stop);
            (probe, std::thread::current().id())
        })
    };
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
    let (probe, caller, got) = run_probe(Probe::new(0.01, ticks), Some(Duration::from_millis(5)));
    assert_eq!(probe.log.len(), ticks);
    for (i, &(now, due, _, _)) in probe.log.iter().enumerate() {
        assert!(now >= due, "tick {i} at {now} before its wake {due}");
        assert!((due - i as f64 * 0.01).abs() < 1e-9, "tick {i} due {due}");
    }
    let first_fed = probe
        .log
        .iter()
        .position(|&(.., handed)| handed > 0)
        .unwrap_or_else(|| panic!("no sample handed: {:?}", probe.log));
    // From the tick after the first sample on, on Zenoh's thread (back on
    // the caller only after a tick late by more than `STALL`, on a loaded
    // machine).
    let after = &probe.log[first_fed + 1..];
    assert!(
        after.first().is_some_and(|&(_, _, t, _)| t != caller),
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
        let (probe, caller, got) = run_probe(Probe::new(period, 100), feed);
        assert_eq!(probe.log.len(), 100);
        assert!(probe.log.iter().all(|&(now, due, _, _)| now >= due));
        assert!(
            probe.log.iter().all(|&(_, _, t, _)| t == caller),
            "period {period}: {:?}",
            probe.log
        );
        assert_eq!(got, 100);
    }
}
