use super::*;
use crate::runtime::testing::{Periodic, count};

/// A [`Periodic`] ticking every `period` s `ticks` times, hearing every
/// `t/*/n` and publishing on `t/<period in ms>/n`.
fn echo(period: f64, ticks: usize) -> Periodic {
    Periodic::new(
        period,
        ticks,
        "t/*/n",
        &format!("t/{}/n", (period * 1000.0) as u32),
    )
}

#[test]
fn the_bus_delivers_in_order_on_the_fake_clock() {
    let mut bus = Bus::new();
    let a = bus.add(echo(0.1, 11), 0.0);
    let b = bus.add(echo(0.25, 5), 0.5);
    // 30 ms from a to b, 10 ms back; a drops its message sent at 0.3.
    bus.link = Box::new(move |from, _, t| match from {
        0 if (t - 0.3).abs() < 1e-9 => None,
        0 => Some(0.03),
        _ => Some(0.01),
    });
    bus.run_until(10.0);
    assert_eq!(bus.now(), 10.0);
    let ea: &Periodic = bus.task(a).unwrap_or_else(|| panic!("a Periodic"));
    let eb: &Periodic = bus.task(b).unwrap_or_else(|| panic!("a Periodic"));
    // Each ticked exactly at its wakes, (0, …, 1.0) on its own clock, and
    // no more once it stopped.
    for (e, period, ticks) in [(ea, 0.1, 11), (eb, 0.25, 5)] {
        assert_eq!(e.log.len(), ticks);
        for (k, tick) in e.log.iter().enumerate() {
            assert!((tick.due - k as f64 * period).abs() < 1e-9, "{:?}", e.log);
            assert!((tick.now - tick.due).abs() < 1e-9, "{:?}", e.log);
        }
    }
    assert!(!bus.is_running(a) && !bus.is_running(b));
    // b hears a's messages 30 ms later on its clock (started at 0.5),
    // in order, all but the one dropped; and its own 10 ms later, but
    // not the last (sent as it stopped: its input was closed).
    let from_a: Vec<(f64, u64)> = eb
        .heard
        .iter()
        .filter(|h| h.1 == "t/100/n")
        .map(|h| (h.0, count(&h.2)))
        .collect();
    let expected: Vec<(f64, u64)> = (0..=10)
        .filter(|&k| k != 3)
        .map(|k| (k as f64 * 0.1 + 0.03 - 0.5, k))
        .filter(|&(at, _)| at >= -0.5)
        .collect();
    assert_eq!(from_a.len(), expected.len());
    for (got, want) in from_a.iter().zip(&expected) {
        assert!(
            (got.0 - want.0).abs() < 1e-9 && got.1 == want.1,
            "{from_a:?}"
        );
    }
    let own: Vec<u64> = eb
        .heard
        .iter()
        .filter(|h| h.1 == "t/250/n")
        .map(|h| count(&h.2))
        .collect();
    assert_eq!(own, vec![0, 1, 2, 3]);
    // a hears b 10 ms after b sent, b's clock 0.5 ahead of a's.
    let first = ea.heard.iter().find(|h| h.1 == "t/250/n").map(|h| h.0);
    assert!(first.is_some_and(|t| (t - 0.51).abs() < 1e-9), "{first:?}");
    // Times seen are in order, and the log is the publications in order.
    assert!(ea.heard.windows(2).all(|w| w[0].0 <= w[1].0));
    assert!(eb.heard.windows(2).all(|w| w[0].0 <= w[1].0));
    assert_eq!(bus.log.len(), 16);
    assert!(bus.log.windows(2).all(|w| w[0].t <= w[1].t));
    let reported = bus.take::<Periodic>(a).and_then(|e| e.report().ok());
    assert_eq!(reported, Some(11));
}
