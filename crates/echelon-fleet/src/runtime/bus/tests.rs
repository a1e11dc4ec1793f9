use super::*;

/// Publishes its tick count on `out` every `period`, records what it hears.
struct Echo {
    period: f64,
    next: f64,
    ticks: u64,
    heard: Vec<(f64, String, Vec<u8>)>,
    until: f64,
}

impl Echo {
    fn new(period: f64, until: f64) -> Echo {
        Echo {
            period,
            next: 0.0,
            ticks: 0,
            heard: Vec::new(),
            until,
        }
    }
}

impl Task for Echo {
    type Report = u64;
    fn inputs(&self) -> Vec<String> {
        vec!["t/*/n".into()]
    }
    fn outputs(&self) -> Vec<String> {
        vec![format!("t/{}/n", (self.period * 1000.0) as u32)]
    }
    fn on_input(&mut self, _: usize, s: &Sample<'_>) -> Result<(), FleetError> {
        self.heard
            .push((s.at, s.key.to_owned(), s.payload.to_vec()));
        Ok(())
    }
    fn next_wake(&self) -> f64 {
        self.next
    }
    fn tick(&mut self, now: f64, out: &mut dyn Outputs) -> Result<Flow, FleetError> {
        if now < self.next {
            return Ok(Flow::Continue);
        }
        out.publish(0, &self.ticks.to_le_bytes())?;
        self.ticks += 1;
        self.next += self.period;
        Ok(if self.next > self.until {
            Flow::Stop
        } else {
            Flow::Continue
        })
    }
    fn report(self) -> Result<u64, FleetError> {
        Ok(self.ticks)
    }
}

fn n(bytes: &[u8]) -> u64 {
    u64::from_le_bytes(bytes.try_into().unwrap_or_default())
}

#[test]
fn the_bus_delivers_in_order_on_the_fake_clock() {
    let mut bus = Bus::new();
    let a = bus.add(Echo::new(0.1, 1.0), 0.0);
    let b = bus.add(Echo::new(0.25, 1.0), 0.5);
    // 30 ms from a to b, 10 ms back; a drops its message sent at 0.3.
    bus.link = Box::new(move |from, _, t| match from {
        0 if (t - 0.3).abs() < 1e-9 => None,
        0 => Some(0.03),
        _ => Some(0.01),
    });
    bus.run_until(10.0);
    assert_eq!(bus.now(), 10.0);
    let ea: &Echo = bus.task(a).unwrap_or_else(|| panic!("an Echo"));
    let eb: &Echo = bus.task(b).unwrap_or_else(|| panic!("an Echo"));
    // Stopped past `until`: 11 ticks (0, …, 1.0), 5 ticks (0, …, 1.0).
    assert_eq!((ea.ticks, eb.ticks), (11, 5));
    assert!(!bus.is_running(a) && !bus.is_running(b));
    // b hears a's messages 30 ms later on its clock (started at 0.5),
    // in order, all but the one dropped; and its own 10 ms later, but
    // not the last (sent as it stopped: its input was closed).
    let from_a: Vec<(f64, u64)> = eb
        .heard
        .iter()
        .filter(|h| h.1 == "t/100/n")
        .map(|h| (h.0, n(&h.2)))
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
        .map(|h| n(&h.2))
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
    let reported = bus.take::<Echo>(a).and_then(|e| e.report().ok());
    assert_eq!(reported, Some(11));
}
