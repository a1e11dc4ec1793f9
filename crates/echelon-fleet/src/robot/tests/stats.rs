//! A robot's counters: once per fleet second, at its own place in the
//! second ([`crate::robot::tick::stats_phase`]), so that robots that set
//! their clocks on the same reference sample do not all publish at once.

use proptest::prelude::*;

use super::*;
use crate::robot::tick::stats_phase;

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    /// Any `k` agents in a row (a host's, a fleet's) spread their places
    /// over the second: no window of `1/k` s holds more than three of them
    /// (the golden ratio's three-gap bound), each place in `[0, 1)`.
    #[test]
    fn consecutive_agents_spread_their_counters_over_the_second(
        first in 1u32..1_000_000, k in 2usize..1200,
    ) {
        let mut places: Vec<f64> = (0..k as u32).map(|i| stats_phase(first + i)).collect();
        prop_assert!(places.iter().all(|p| (0.0..1.0).contains(p)), "{places:?}");
        places.sort_by(f64::total_cmp);
        let width = 1.0 / k as f64;
        let wrapped: Vec<f64> = places.iter().chain(places.iter()).enumerate()
            .map(|(i, p)| if i < k { *p } else { p + 1.0 }).collect();
        let mut end = 0;
        for start in 0..k {
            while end < wrapped.len() && wrapped[end] < wrapped[start] + width {
                end += 1;
            }
            prop_assert!(end - start <= 3, "{} places within {width} s from {}", end - start, wrapped[start]);
        }
    }
}

/// Two robots fed the same reference samples publish their counters once
/// per fleet second each, every second, at their own places in it: not in
/// the same tick.
#[test]
fn robots_on_the_same_samples_publish_their_counters_apart() {
    let text = FAST_CIRCLE.replace("leader = 1\n", "leader = \"reference\"\n");
    let s = Scenario::parse(&text, "test", None).unwrap_or_else(|e| panic!("{e}"));
    let reference = reference(&s);
    let mut robots = [
        robot(&s, 1, FaultSpec::default()),
        robot(&s, 2, FaultSpec::default()),
    ];
    let mut at: [Vec<f64>; 2] = [Vec::new(), Vec::new()];
    let mut buf = Vec::new();
    for k in 0..500u64 {
        let t = 0.01 * k as f64;
        reference_message(&mut buf, k, t, &reference);
        for (r, at) in robots.iter_mut().zip(&mut at) {
            r.on_message(&buf, t);
            if let Some(stats) = r.tick(t).stats {
                at.push(stats.t);
            }
        }
    }
    for (agent, at) in [1u32, 2].iter().zip(&at) {
        assert_eq!(at.len(), 5, "agent {agent}: counters at {at:?}");
        let place = stats_phase(*agent);
        for (n, t) in at.iter().enumerate() {
            // The first tick at or after its place in second n.
            assert!(
                *t >= n as f64 + place - 1e-9 && *t < n as f64 + place + 0.01 + 1e-9,
                "agent {agent}: {at:?}"
            );
        }
    }
    assert!(
        at[0]
            .iter()
            .all(|a| at[1].iter().all(|b| (a - b).abs() > 0.005)),
        "{at:?}"
    );
}
