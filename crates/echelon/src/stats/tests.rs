//! The statistics' tests: the closest-approach accumulator against brute
//! force and against `SafetyWatch`.

#![allow(clippy::unwrap_used)] // tests fail loudly by design

use proptest::prelude::*;

use super::{Approach, ClosestApproach, SafetyWatch};
use crate::Observer;
use crate::model::State;
use crate::safety::Obstacle;
use crate::scenario::{Overrides, Scenario};
use crate::sim::{Frame, ObserverError};

fn state([x, y, theta]: [f64; 3]) -> State {
    State {
        x,
        y,
        theta,
        v: 0.0,
        omega: 0.0,
    }
}

/// The closest approach by brute force over every instant and pair:
/// the smallest distance, the first instant it occurs at and the first
/// pair `(j, i)`, `j < i` in the order of `i` then `j`; the smallest
/// clearance over every instant, robot and obstacle.
fn brute(
    frames: &[(f64, Vec<State>)],
    l: &[f64],
    obstacles: &[Obstacle],
) -> (f64, f64, [usize; 2], f64) {
    let (mut best, mut at, mut pair, mut clear) = (f64::INFINITY, 0.0, [0, 0], f64::INFINITY);
    for (t, states) in frames {
        let p: Vec<[f64; 2]> = states
            .iter()
            .zip(l)
            .map(|(s, &l)| [s.x + l * s.theta.cos(), s.y + l * s.theta.sin()])
            .collect();
        for i in 0..p.len() {
            for j in 0..i {
                let d = (p[i][0] - p[j][0]).hypot(p[i][1] - p[j][1]);
                if d < best {
                    (best, at, pair) = (d, *t, [j + 1, i + 1]);
                }
            }
            for o in obstacles {
                let c = (p[i][0] - o.x()).hypot(p[i][1] - o.y()) - o.r();
                clear = clear.min(c);
            }
        }
    }
    (best, at, pair, clear)
}

proptest! {
    /// For random points over time, the accumulator's minimum is the
    /// brute-force minimum over every pair and instant, with its pair
    /// and time; the clearance is the brute-force one; feeding every
    /// agent through `record_some` gives the same as `record`.
    #[test]
    fn approach_is_the_brute_force_minimum(
        n in 2usize..6,
        l in prop::collection::vec(0.0..0.5f64, 6),
        raw in prop::collection::vec(
            prop::collection::vec((-5.0..5.0f64, -5.0..5.0f64, -4.0..4.0f64), 6),
            1..30,
        ),
        obstacles in prop::collection::vec((-5.0..5.0f64, -5.0..5.0f64, 0.1..1.0f64), 0..3),
    ) {
        let l = &l[..n];
        let obstacles: Vec<Obstacle> = obstacles
            .iter()
            .map(|&(x, y, r)| Obstacle::new(x, y, r).unwrap())
            .collect();
        let frames: Vec<(f64, Vec<State>)> = raw
            .iter()
            .enumerate()
            .map(|(k, f)| (0.1 * k as f64, f[..n].iter().map(|&(x, y, th)| state([x, y, th])).collect()))
            .collect();
        let mut a = Approach::new(l.to_vec(), 0.3, obstacles.clone());
        let mut b = a.clone();
        for (t, states) in &frames {
            a.record(*t, states);
            b.record_some(*t, states.iter().enumerate());
        }
        let (best, at, pair, clear) = brute(&frames, l, &obstacles);
        let c = a.closest();
        prop_assert!((c.min_distance - best).abs() <= 1e-12 * (1.0 + best), "{} vs {}", c.min_distance, best);
        prop_assert_eq!(c.min_distance_t, at);
        prop_assert_eq!(c.min_distance_agents, pair);
        prop_assert!(pair[0] < pair[1] && pair[1] <= n);
        match c.min_obstacle_clearance {
            Some(got) => prop_assert!((got - clear).abs() <= 1e-12 * (1.0 + clear.abs())),
            None => prop_assert!(obstacles.is_empty()),
        }
        prop_assert_eq!(c.radius, 0.3);
        prop_assert!(a.paired());
        prop_assert_eq!(&a, &b);
    }

    /// Shown a subset of the agents, it is the minimum over that subset
    /// only, its pair named by the agents' own numbers.
    #[test]
    fn a_subset_is_named_by_its_agents(
        pts in prop::collection::vec((-5.0..5.0f64, -5.0..5.0f64), 5),
        keep in prop::collection::vec(any::<bool>(), 5),
    ) {
        let states: Vec<State> = pts.iter().map(|&(x, y)| state([x, y, 0.0])).collect();
        let kept: Vec<(usize, &State)> = states.iter().enumerate().filter(|(i, _)| keep[*i]).collect();
        let mut a = Approach::new(vec![0.0; 5], 0.3, Vec::new());
        a.record_some(1.0, kept.iter().copied());
        let sub: Vec<State> = kept.iter().map(|(_, s)| **s).collect();
        let (best, _, pair, _) = brute(&[(1.0, sub)], &vec![0.0; kept.len()], &[]);
        prop_assert_eq!(a.paired(), kept.len() >= 2);
        if kept.len() >= 2 {
            prop_assert_eq!(a.closest().min_distance.to_bits(), best.to_bits());
            let named = [kept[pair[0] - 1].0 + 1, kept[pair[1] - 1].0 + 1];
            prop_assert_eq!(a.closest().min_distance_agents, named);
        }
    }
}

/// Fed every frame of a run, the accumulator gives exactly the
/// geometric part of `SafetyWatch`'s report (with and without obstacles).
#[test]
fn fed_a_runs_frames_it_is_the_watchs_report() {
    for name in ["crossing", "obstacle-slalom"] {
        let run = Scenario::builtin(name)
            .unwrap()
            .build(&Overrides::default())
            .unwrap();
        let mut approach = Approach::of(&run.plan).unwrap();
        let sim = &mut run.simulation();
        let mut every = |f: &Frame<'_>| -> Result<(), ObserverError> {
            approach.record(f.t, f.states);
            Ok(())
        };
        let mut watch = SafetyWatch::default();
        sim.run(&mut [&mut every as &mut dyn Observer, &mut watch])
            .unwrap();
        let report: ClosestApproach = watch.report().unwrap().closest.clone();
        assert_eq!(&report, approach.closest(), "{name}");
        assert!(report.min_distance.is_finite());
        assert_eq!(
            report.min_obstacle_clearance.is_some(),
            name == "obstacle-slalom"
        );
    }
}
