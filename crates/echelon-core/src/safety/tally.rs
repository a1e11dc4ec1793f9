//! What a robot's safety filter did over a run, counted one way wherever it
//! runs: the simulator's `summary.json` (`safety.agents`, which Python's
//! `Simulation` reads too) and a fleet robot's report (`safety`).

use super::Outcome;

/// A robot's safety filter's answers, counted.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Tally {
    /// Commands that went through the filter.
    pub steps: u64,
    /// Of them, those it changed (filtered or braked).
    pub active: u64,
    /// Braked because the QP was infeasible (or the solver failed).
    pub infeasible: u64,
    /// Braked because a neighbour within range stayed stale past the hold
    /// (a fleet robot's; never infeasible too).
    pub stale_brakes: u64,
    /// Smallest distance from its point to a neighbour's point it saw
    /// within range, m (infinite: none seen).
    pub min_distance: f64,
}

impl Default for Tally {
    fn default() -> Tally {
        Tally {
            steps: 0,
            active: 0,
            infeasible: 0,
            stale_brakes: 0,
            min_distance: f64::INFINITY,
        }
    }
}

impl Tally {
    /// Counts one command through the filter: its `outcome`, whether it was
    /// braked for a `stale` neighbour, and the smallest distance to a
    /// neighbour it saw (infinite: none).
    pub fn record(&mut self, outcome: Outcome, stale: bool, min_distance: f64) {
        self.steps += 1;
        self.active += u64::from(outcome != Outcome::Nominal);
        if stale {
            self.stale_brakes += 1;
        } else if outcome == Outcome::Braked {
            self.infeasible += 1;
        }
        if min_distance < self.min_distance {
            self.min_distance = min_distance;
        }
    }

    /// [`Tally::min_distance`] when one was seen.
    pub fn closest(&self) -> Option<f64> {
        self.min_distance.is_finite().then_some(self.min_distance)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_answer_is_counted_once_where_it_belongs() {
        let mut t = Tally::default();
        assert_eq!(t.closest(), None);
        t.record(Outcome::Nominal, false, f64::INFINITY);
        t.record(Outcome::Filtered, false, 0.5);
        t.record(Outcome::Braked, false, 0.3);
        t.record(Outcome::Braked, true, 0.4);
        assert_eq!(
            (t.steps, t.active, t.infeasible, t.stale_brakes),
            (4, 3, 1, 1)
        );
        assert_eq!(t.closest(), Some(0.3));
        // A NaN distance is not a distance seen.
        t.record(Outcome::Nominal, false, f64::NAN);
        assert_eq!(t.closest(), Some(0.3));
    }
}
