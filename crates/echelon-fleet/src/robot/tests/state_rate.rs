//! `[fleet] state_rate`: a robot no other robot reads publishes its state
//! at that rate while it follows; one that is read publishes every tick.

use proptest::prelude::*;

use super::*;

/// The fast circle with `state_rate` (Hz) under `[fleet]`; with
/// `alone`, agent 2 follows the reference (nobody reads agent 1); with
/// `safety`, every robot filters.
fn with_state_rate(rate: f64, alone: bool, safety: bool) -> Scenario {
    let mut text = FAST_CIRCLE.replace("[fleet]\n", &format!("[fleet]\nstate_rate = {rate:?}\n"));
    if alone {
        text = text.replace("leader = 1\n", "leader = \"reference\"\n");
    }
    if safety {
        text = text.replacen("[fleet]\n", "[safety]\nradius = 0.05\n\n[fleet]\n", 1);
    }
    Scenario::parse(&text, "test", None).unwrap_or_else(|e| panic!("{e}"))
}

/// How many ticks publish a state: `control_rate / state_rate` rounded.
fn expected_every(rate: f64) -> u64 {
    (100.0 / rate).round().max(1.0) as u64
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(32))]

    /// Who is read publishes every tick; who is not, every
    /// `control_rate / state_rate` ticks; a safety filter anywhere reads
    /// everyone.
    #[test]
    fn only_a_robot_nobody_reads_publishes_less_often(rate in 0.1f64..100.0) {
        let every = |s: &Scenario, k: u32| crate::testing::robot_config(s, k, FaultSpec::default()).state_every;
        let chain = with_state_rate(rate, false, false);
        prop_assert_eq!(every(&chain, 1), 1, "agent 1 leads agent 2");
        prop_assert_eq!(every(&chain, 2), expected_every(rate));
        let alone = with_state_rate(rate, true, false);
        prop_assert_eq!(every(&alone, 1), expected_every(rate));
        let filtered = with_state_rate(rate, true, true);
        prop_assert_eq!((every(&filtered, 1), every(&filtered, 2)), (1, 1));
    }

    /// Fed the reference every tick for `ticks` ticks, a robot nobody
    /// reads publishes on the first tick and every `state_every`-th after,
    /// and nothing else about its run changes (its final state and counters
    /// are those of the same robot publishing every tick).
    #[test]
    fn a_robot_publishes_every_state_every_th_tick(rate in 1.0f64..100.0, ticks in 1usize..400) {
        let run = |s: &Scenario| {
            let mut r = robot(s, 1, FaultSpec::default());
            let reference = reference(s);
            let mut buf = Vec::new();
            let mut published = Vec::new();
            for k in 0..ticks {
                let t = 0.01 * k as f64;
                reference_message(&mut buf, k as u64, t, &reference);
                r.on_message(&buf, t);
                if let Some((_, state)) = r.tick(t).publish {
                    published.push(state.t);
                }
            }
            (published, r.report())
        };
        let (sparse, report) = run(&with_state_rate(rate, true, false));
        let (dense, full) = run(&with_state_rate(100.0, true, false));
        let every = expected_every(rate) as usize;
        prop_assert_eq!(dense.len(), ticks);
        let want: Vec<f64> = dense.iter().copied().step_by(every).collect();
        prop_assert_eq!(sparse, want);
        prop_assert_eq!(report.final_error, full.final_error);
        prop_assert_eq!(report.counters, full.counters);
    }
}
