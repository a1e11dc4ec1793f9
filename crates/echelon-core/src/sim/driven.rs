//! Stepping under commands from outside the simulator (a Python controller,
//! Robotarium-style): the caller's command for each agent goes through the
//! agent's act step (its acceleration limit) and is held over the RK4 step,
//! exactly as a sampled controller's command is; the drive's limits,
//! the plant and odometry then apply as in [`Simulation::step`].
//!
//! A scenario's safety filter applies to the caller's commands as to a
//! sampled law's, unless the caller turns it off.
//!
//! A continuous-time controller is evaluated in each RK4 stage; the caller
//! gives [`Simulation::step_by`] its law, which is called where the
//! simulator calls its own.
//!
//! [`Simulation::sensed`] and [`Simulation::leader_view`] give the caller
//! what the simulator's own law is given (the pose its odometry estimates,
//! the leader motion and offsets of eqs. 4–6), so that a controller written
//! outside with [`crate::law::control::law`] reproduces a sampled run's bits.

use std::cell::RefCell;

use super::system::Source;
use super::{Now, SafetyOutput, Simulation, system};
use crate::error::{ParamError, SimError};
use crate::formation::Leader;
use crate::formation::agent::Command;
use crate::formation::follow::LeaderView;
use crate::law::control::{LeaderMotion, Offset};
use crate::model::{Input, State};
use crate::safety::Outcome;

impl Simulation {
    /// What agent `i`'s controller senses of itself: its odometry estimate
    /// when it dead-reckons (eqs. 32–35), else its true state.
    pub fn sensed(&self, i: usize) -> State {
        system::sensed(&self.odometers, &self.state, i)
    }

    /// The leader motion `p_d, ṗ_d, p̈_d` and the offsets `L_X, L_Y, L̇_Y,
    /// L̈_Y` (eqs. 4–6) agent `i`'s law is given now, as in `echelon run`.
    /// A robot leader `j` is seen through its sensed state, at the speeds
    /// its base moves at, accelerating under `commands[j]` (the caller
    /// computes leaders first: [`crate::formation::Formation::order`]).
    /// `commands` holds one command per agent; only the leader's is read.
    pub fn leader_view(&self, i: usize, commands: &[Command]) -> (LeaderMotion, Offset) {
        let agents = self.sys.plan.agents();
        let a = &agents[i];
        match a.leader() {
            Leader::Reference => {
                let jet = self.sys.jet(self.time());
                LeaderView::Reference(&jet).resolve(&a.placement())
            }
            Leader::Agent(j) => {
                let leader = &agents[j];
                let sensed = self.sensed(j);
                let command = leader.act(self.time(), &sensed, commands[j], None).command;
                let applied = leader.drive().actuate(command);
                let dv = leader.drive().derivative(&self.state[j], &applied).v;
                let speeds = leader.drive().speeds(&self.state[j], &applied);
                system::robot_leader(leader.drive(), sensed, speeds, dv).resolve(&a.placement())
            }
        }
    }

    /// Advances one RK4 step under `commands`, one per agent in its drive's
    /// terms (`u1, u2` for a torque-driven robot, `v*, ω*` for a velocity
    /// base; the other kind applies as zero), held over the step. From the
    /// first call on the simulation's own controller no longer samples: the
    /// frames show the caller's commands.
    ///
    /// With `filter` and a scenario with `[safety]`, each filtering agent's
    /// command then goes through its safety filter exactly as a sampled law's
    /// does in `echelon run` (the simulator's own filter step, with the
    /// neighbours its controller sees); [`Simulation::safety_outputs`] says
    /// what each filter did. The filters' period is the scenario's controller
    /// period (`dt` without one), whatever the caller holds its commands for.
    /// Returns whether the filter ran (`filter` and the scenario has one).
    pub fn step_with(&mut self, commands: &[Command], filter: bool) -> Result<bool, SimError> {
        let n = self.state.len();
        if commands.len() != n {
            return Err(SimError::Param {
                context: "step".into(),
                source: ParamError::new(
                    "commands",
                    commands.len() as f64,
                    format!("needs one command per agent ({n})"),
                ),
            });
        }
        let t = self.time();
        for (i, c) in commands.iter().enumerate() {
            let me = self.sensed(i);
            self.held[i] = self.sys.plan.agents()[i].act(t, &me, *c, None).command;
        }
        // The held commands are the caller's from now on: never a sample.
        self.hold_every = u64::MAX;
        self.evaluate_now(Now::Held, true);
        let filtered = filter && self.safety.is_some();
        if filtered {
            self.filter();
        } else if let Some(safety) = self.safety.as_deref_mut() {
            // Unfiltered: every command passes as it is.
            for (o, h) in safety.out.iter_mut().zip(&self.held) {
                o.sampled = false;
                o.outcome = Outcome::Nominal;
                o.deadlock = false;
                o.nominal = h.values();
                o.filtered = h.values();
            }
        }
        self.fresh = true;
        self.step()?;
        Ok(filtered)
    }

    /// What each agent's safety filter did (empty without `[safety]`),
    /// without evaluating anything: after [`Simulation::step_with`], the
    /// filtering at the start of that step (`sampled` is cleared by the
    /// evaluation that ends the step); after one with the filter off, every
    /// command passed as it was (`min_distance` is the last filtering's).
    pub fn safety_outputs(&self) -> &[SafetyOutput] {
        self.safety.as_ref().map_or(&[], |s| &s.out[..])
    }

    /// Advances one RK4 step with `law` in place of every agent's own law,
    /// evaluated where `echelon run` evaluates a continuous-time
    /// controller's: in each of RK4's four stages, leaders before followers
    /// (and at the new state, to settle a velocity base's speeds). `law(i, t,
    /// sensed, motion, offset)` is agent `i`'s command (in its drive's terms)
    /// at `t` from what it senses and what its own law is given then
    /// ([`Simulation::leader_view`]'s leader motion and offsets, at the
    /// stage); it goes through the agent's act step, limits and plant as its
    /// own law's does. Only for a continuous-time controller: a scenario that
    /// samples its controller (or filters, or was stepped by
    /// [`Simulation::step_with`]) is refused. When `law` fails, the step
    /// stops there and the error is returned: nothing has moved, unless it
    /// failed settling a velocity base (the step is then taken, the base's
    /// speeds unsettled).
    pub fn step_by<E>(
        &mut self,
        mut law: impl FnMut(usize, f64, &State, &LeaderMotion, &Offset) -> Result<Command, E>,
    ) -> Result<(), StepByError<E>> {
        if self.hold_every != 0 {
            return Err(StepByError::Sim(SimError::Timing(
                "step_by: this simulation's controller is sampled (controller_period, \
                 [safety] or step_with): its commands are held over the step, give them to step_with"
                    .into(),
            )));
        }
        let failed: RefCell<Option<E>> = RefCell::new(None);
        let mut caller = |i: usize, t: f64, me: &State, m: &LeaderMotion, o: &Offset| {
            if failed.borrow().is_none() {
                match law(i, t, me, m, o) {
                    Ok(c) => return c,
                    Err(e) => *failed.borrow_mut() = Some(e),
                }
            }
            // After a failure the rest of the stage is thrown away.
            Command::Torque(Input::default())
        };
        let abort = || SimError::Observer("the caller's law failed".into());
        self.evaluate_now(Now::Caller(&mut caller), true);
        self.fresh = failed.borrow().is_none();
        let stepped = if self.fresh {
            self.advance(|sys, _, odo, t, x, dx, sp| {
                sys.evaluate_by(t, x, Source::Caller(&mut caller), odo, None, dx, sp);
                if failed.borrow().is_some() {
                    Err(abort())
                } else {
                    Ok(())
                }
            })
        } else {
            Err(abort())
        };
        if stepped.is_ok() && self.velocity_agents {
            self.evaluate_now(Now::Caller(&mut caller), true);
            if failed.borrow().is_none() {
                self.settle_to_outputs();
            }
        }
        self.fresh = false;
        match (failed.into_inner(), stepped) {
            (Some(e), _) => Err(StepByError::Law(e)),
            (None, Err(e)) => Err(StepByError::Sim(e)),
            (None, Ok(())) => Ok(()),
        }
    }
}

/// Why [`Simulation::step_by`] failed.
#[derive(Debug)]
pub enum StepByError<E> {
    /// The caller's law failed.
    Law(E),
    /// The step did (a sampled controller, a divergence).
    Sim(SimError),
}
