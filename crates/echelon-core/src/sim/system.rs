//! The formation evaluated at one instant: each agent's law, in leader
//! order, and its plant's derivative under the command.

use super::AgentOutput;
use crate::formation::Leader;
use crate::formation::agent::{Command, Drive};
use crate::formation::follow::{LeaderView, follow};
use crate::law::control::{LawOutput, LeaderMotion, Offset, errors};
use crate::law::kinematic::kinematic_law;
use crate::model::State;
use crate::model::base::Backup;
use crate::odometry::Odometer;
use crate::reference::{Jet, Order, Trajectory};
use crate::sim::plan::Plan;

/// What agent `j`'s controller senses of itself in states `x`: its odometry
/// estimate when it dead-reckons (eqs. 32–35), else its true state.
#[inline]
pub(super) fn sensed(odometers: &[Option<Odometer>], x: &[State], j: usize) -> State {
    match odometers.get(j) {
        Some(Some(o)) => o.measure(&x[j]),
        _ => x[j],
    }
}

/// What a follower's law knows of leader robot `drive` in `state`: a
/// velocity base moves at `speeds` (`v, ω` of [`Drive::speeds`]), not at the
/// state's own; `dv` is its `v̇` now.
#[inline]
pub(super) fn robot_leader(
    drive: &Drive,
    state: State,
    speeds: [f64; 4],
    dv: f64,
) -> LeaderView<'static> {
    let state = match drive {
        Drive::Torque { .. } => state,
        Drive::Velocity(_) => State {
            v: speeds[0],
            omega: speeds[1],
            ..state
        },
    };
    LeaderView::Robot { state, dv }
}

/// A law from outside the simulator ([`Simulation::step_by`]): agent `i`'s
/// command at `t` from what it senses and what its law is given (leader
/// motion and offsets, eqs. 4–6).
///
/// [`Simulation::step_by`]: super::Simulation::step_by
pub(super) type CallerLaw<'a> =
    dyn FnMut(usize, f64, &State, &LeaderMotion, &Offset) -> Command + 'a;

/// Where each agent's command comes from in [`System::evaluate_by`].
pub(super) enum Source<'a, 'b> {
    /// Its own law, through its act step.
    Law,
    /// Held commands (a sampled controller between samples, or a caller's),
    /// already through the act step.
    Held(&'a [Command]),
    /// A caller's law in place of its own, through its act step.
    Caller(&'a mut CallerLaw<'b>),
}

/// Immutable description of the system being simulated.
#[derive(Debug, Clone)]
pub(super) struct System {
    /// The plan it runs (agents, formation, reference).
    pub(super) plan: Plan,
    pub(super) order: Order,
    pub(super) uses_reference: bool,
    /// Each velocity base's backward-travel budget, when it has a
    /// `reverse_limit` ([`Backup`]): brought up to date and planned for the
    /// next step after every step (one plan for the step's four stages).
    pub(super) backup: Vec<Option<Backup>>,
    /// How long a command is held: the sampling period, else the step.
    pub(super) backup_period: f64,
}

impl System {
    /// Agent `i`'s command `cmd` for it in `me` within its backup budget
    /// ([`Backup::apply`]; unchanged without a `reverse_limit`).
    #[inline]
    pub(super) fn within_backup(&self, i: usize, me: &State, cmd: Command) -> Command {
        match (&self.backup[i], self.plan.agents()[i].drive(), cmd) {
            (Some(b), Drive::Velocity(r), Command::Velocity(c)) => {
                Command::Velocity(b.apply(&r.base(), me, c).0)
            }
            _ => cmd,
        }
    }

    /// The reference's jet at `t`, to the order the laws need (zero when no
    /// agent follows the reference).
    #[inline]
    pub(super) fn jet(&self, t: f64) -> Jet {
        if self.uses_reference {
            self.plan.reference().eval(t, self.order)
        } else {
            Jet::default()
        }
    }

    /// Evaluates every agent at time `t` and states `x`: state derivatives into
    /// `dx`, the velocities each robot moves at into `speeds` and, when `out`
    /// is given (RK4's first stage, which observers see), controller outputs
    /// into it. With `held`, the commands are held values (sampled controller)
    /// instead of fresh law outputs. With odometers, the law acts on what they
    /// measure (eqs. 32–35) while `e`, `z` in `out` are those of the true state.
    /// A velocity base's command is limited ([`crate::model::base::VelocityBase::limit`])
    /// before it drives the base.
    #[inline]
    #[allow(clippy::too_many_arguments)]
    pub(super) fn evaluate(
        &self,
        t: f64,
        x: &[State],
        held: Option<&[Command]>,
        odometers: &[Option<Odometer>],
        out: Option<&mut [AgentOutput]>,
        dx: &mut [State],
        speeds: &mut [[f64; 4]],
    ) {
        let source = held.map_or(Source::Law, Source::Held);
        self.evaluate_by(t, x, source, odometers, out, dx, speeds);
    }

    /// [`System::evaluate`] with the commands from `source`.
    #[inline]
    #[allow(clippy::too_many_arguments)]
    pub(super) fn evaluate_by(
        &self,
        t: f64,
        x: &[State],
        mut source: Source<'_, '_>,
        odometers: &[Option<Odometer>],
        mut out: Option<&mut [AgentOutput]>,
        dx: &mut [State],
        speeds: &mut [[f64; 4]],
    ) {
        if let (None, Source::Held(h)) = (&out, &source) {
            // Between samples of a sampled controller, with nobody looking at
            // the law's outputs: only the plant moves.
            for (i, a) in self.plan.agents().iter().enumerate() {
                let applied = a.drive().actuate(h[i]);
                dx[i] = a.drive().derivative(&x[i], &applied);
                speeds[i] = a.drive().speeds(&x[i], &applied);
            }
            return;
        }
        let jet = self.jet(t);
        let sensed = |j: usize| sensed(odometers, x, j);
        for &i in self.plan.formation().order() {
            let a = &self.plan.agents()[i];
            // What the law knows of the leader, from a state of robot j: the
            // leader was evaluated first, so dx[j].v is its v̇ now and
            // speeds[j] the velocities its base moves at.
            let view = |state: State, j: usize| {
                robot_leader(self.plan.agents()[j].drive(), state, speeds[j], dx[j].v)
            };
            let leader = match a.leader() {
                Leader::Reference => LeaderView::Reference(&jet),
                Leader::Agent(j) => view(sensed(j), j),
            };
            let me = sensed(i);
            let law = follow(a, &me, leader);
            let (LawOutput { e, z, .. }, motion, offset) = (law.law, law.leader, law.offset);
            let (e_true, z_true) = if out.is_none() || odometers.is_empty() {
                (e, z)
            } else {
                // The same errors from the true states of the robot and its leader.
                let (motion, offset) = match a.leader() {
                    Leader::Reference => (motion, offset),
                    Leader::Agent(j) => view(x[j], j).resolve(&a.placement()),
                };
                let s = &x[i];
                match a.drive() {
                    Drive::Torque { .. } => errors(
                        s.x,
                        s.y,
                        s.theta.sin_cos(),
                        s.v,
                        s.omega,
                        motion.p,
                        motion.dp,
                        offset.lx,
                        offset.ly,
                        offset.dly,
                        a.gains().ke(),
                    ),
                    Drive::Velocity(_) => {
                        let k = kinematic_law(s, &motion, &offset, a.gains().ke());
                        (k.e, k.z)
                    }
                }
            };
            // The act step (agent.rs): the law's command through the agent's
            // limits; a sampled controller's held command went through it
            // (and its filter) at the sample.
            let command = match &mut source {
                Source::Law => {
                    self.within_backup(i, &me, a.act(t, &me, law.command(), None).command)
                }
                Source::Held(h) => h[i],
                Source::Caller(f) => self.within_backup(
                    i,
                    &me,
                    a.act(t, &me, f(i, t, &me, &motion, &offset), None).command,
                ),
            };
            let applied = a.drive().actuate(command);
            dx[i] = a.drive().derivative(&x[i], &applied);
            speeds[i] = a.drive().speeds(&x[i], &applied);
            let output = AgentOutput::of(e_true, z_true, e, z, command, &applied);
            if let Some(out) = out.as_deref_mut() {
                out[i] = output;
            }
        }
    }
}
