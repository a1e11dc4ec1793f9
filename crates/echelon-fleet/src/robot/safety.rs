//! A fleet robot's safety filter step (`docs/safety.md`, "In the fleet"):
//! its filter, its neighbour table and its counts.

use echelon::agent::{Command, Guard};
use echelon::model::State;
use echelon::safety::{SafetyFilter, Tally, point};

use crate::neighbours::NeighbourTable;

use super::RobotConfig;

/// A robot's safety filter and what it knows of its neighbours.
#[derive(Debug, Clone)]
pub(super) struct Safety {
    pub(super) filter: SafetyFilter,
    pub(super) table: NeighbourTable,
    pub(super) tally: Tally,
}

/// What a robot's filter step knows of the robot itself.
#[derive(Debug, Clone, Copy)]
pub(super) struct Seen<'a> {
    /// Its state.
    pub(super) me: &'a State,
    /// How uncertain its position estimate is, m.
    pub(super) sigma: f64,
    /// Its law's tracking error ‖e‖, m (the filter's progress measure).
    pub(super) error: f64,
    /// The backward speed its base accepts this period, m/s
    /// ([`Guard::reverse`]).
    pub(super) reverse: f64,
}

impl Safety {
    /// The act step ([`AgentSpec::act`]) through this robot's filter at
    /// local time `local` (fleet time `t`) for a robot as `seen`: the
    /// command for its plant, counted (`docs/safety.md`, "In the fleet").
    pub(super) fn act(
        &mut self,
        config: &RobotConfig,
        local: f64,
        t: f64,
        seen: Seen<'_>,
        nominal: Command,
    ) -> Command {
        let Seen {
            me,
            sigma,
            error,
            reverse,
        } = seen;
        let Some(settings) = config.safety.as_ref() else {
            return config.spec.act(t, me, nominal, None).command;
        };
        let l = config.spec.placement().l();
        let sight = self
            .table
            .build(local, t, point(me, l), settings.config.range, sigma);
        let guard = Guard {
            filter: &mut self.filter,
            sight,
            obstacles: &settings.obstacles,
            error: Some(error),
            reverse,
        };
        let act = config.spec.act(t, me, nominal, Some(guard));
        match act.safety {
            Some(g) => self.tally.record(g.outcome, g.stale, g.min_distance),
            None => self.tally.steps += 1,
        }
        act.command
    }
}
