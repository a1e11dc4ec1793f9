//! What the robot does about its base's hazards: the fleet stop it takes,
//! the backup it plans within the base's reverse limit.

use super::*;

impl<P: Plant> Robot<P> {
    /// The stopping hazards its base reported at its last tick.
    pub fn hazards(&self) -> HazardSet {
        self.hazards
    }

    /// The fleet stop it took (its base reported a hazard) for its driver
    /// to put on its halt key ([`crate::keys::Keys::halt`]), once.
    pub fn take_outgoing(&mut self) -> Option<FleetCommand> {
        self.outgoing.take()
    }

    /// Takes a fleet stop of its own, named after its hazards, and keeps it
    /// for its driver to put ([`Robot::take_outgoing`]).
    pub(super) fn pause_fleet(&mut self, what: &str) {
        let agent = self.config.agent;
        let reason = format!(
            "agent {agent} ({}): its base reports {} ({what})",
            self.config.spec.name(),
            self.hazards.names()
        );
        let stop = FleetCommand::new(
            Order::Stop,
            self.latch.seq() + 1,
            &Member::Robot(agent).identity(),
            &reason,
        );
        self.latch.on_command(stop.clone());
        self.outgoing = Some(stop);
    }

    /// Brings the backup budget ([`Backup`]: how far the robot is behind
    /// its furthest point, measured from its state tick by tick) up to the
    /// robot in `state` and plans the coming period: the backward speed it
    /// allows, m/s (infinite: no limit), for the safety filter to respect
    /// ([`echelon::agent::Guard::reverse`]).
    pub(super) fn plan_backup(&mut self, state: &echelon::model::State) -> f64 {
        let (Some((backup, last)), Some(r)) =
            (self.backup.as_mut(), self.config.spec.velocity_robot())
        else {
            return f64::INFINITY;
        };
        if let Some(p) = last {
            let (sin, cos) = p.theta.sin_cos();
            backup.observe((state.x - p.x) * cos + (state.y - p.y) * sin);
        }
        *last = Some(*state);
        backup.plan(&r.base(), state, self.config.period);
        backup.cap()
    }

    /// `cmd` for the robot in `state` within the period's backup plan
    /// ([`Robot::plan_backup`], [`Backup::apply`]; the command held for one
    /// period).
    pub(super) fn within_backup(
        &self,
        state: &echelon::model::State,
        cmd: echelon::agent::Command,
    ) -> echelon::agent::Command {
        let (Some((backup, _)), Some(r), echelon::agent::Command::Velocity(c)) =
            (self.backup.as_ref(), self.config.spec.velocity_robot(), cmd)
        else {
            return cmd;
        };
        echelon::agent::Command::Velocity(backup.apply(&r.base(), state, c).0)
    }

    /// Reads its base's safety words at fleet time `now`: a stopping
    /// hazard pauses the fleet if it is not stopped yet
    /// ([`Robot::pause_fleet`]), so that this tick is a stopped one, which
    /// commands zero ([`Halt::Hazard`]).
    pub(super) fn check_hazards(&mut self, now: f64) {
        let hazards = self.plant.hazards(now);
        if hazards != self.hazards {
            self.hazards = hazards;
            self.hazard_changes += 1;
        }
        if !hazards.is_empty() && !self.latch.stopped() {
            // The stopped tick that follows commands zero, at this tick.
            self.pause_fleet(&format!("at t = {now:.3} s"));
        }
    }
}
