//! One agent's law evaluation, shared by the simulator
//! ([`crate::sim::Simulation`]) and the fleet's robot process: from what the
//! agent knows of its leader to the leader motion `p_d, ṗ_d, p̈_d`, the offsets
//! `L_X, L_Y` (eqs. 4–6) and the law's output (eq. 13).

use crate::agent::{AgentSpec, Command, Drive};
use crate::base::VelocityCommand;
use crate::control::{LawOutput, LeaderMotion, Offset, law};
use crate::kinematic::kinematic_law;
use crate::lycomp::Placement;
use crate::model::Input;
use crate::model::State;
use crate::reference::Jet;

/// What a follower knows of its leader at one instant.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum LeaderView<'a> {
    /// The virtual leader: the reference's jet (`p_d`, `ṗ_d`, `p̈_d`, and
    /// `p⃛_d`, `p⁗_d` when `L_Y`'s derivatives are exact).
    Reference(&'a Jet),
    /// A leader robot in `state`, accelerating at `dv` (control-law.md,
    /// "Leader velocity and curvature"; `V_d = v`, `ω_d = ω`).
    Robot {
        /// The leader's state (as the follower senses it).
        state: State,
        /// Its `v̇`, m/s².
        dv: f64,
    },
    /// A leader known by its motion and its `V_d`, `ω_d` (a sample received
    /// over a link and advanced to now, or the link-loss policy's guess).
    Motion {
        /// `p_d, ṗ_d, p̈_d`.
        motion: LeaderMotion,
        /// `V_d`, m/s.
        speed: f64,
        /// `ω_d`, rad/s.
        turn_rate: f64,
    },
}

impl LeaderView<'_> {
    /// The leader motion and the offsets `L_X, L_Y, L̇_Y, L̈_Y` (eqs. 4–6) a
    /// follower with `placement` holds it at.
    #[inline]
    pub fn resolve(&self, placement: &Placement) -> (LeaderMotion, Offset) {
        match *self {
            LeaderView::Reference(jet) => (
                LeaderMotion::of_jet(jet),
                placement.offset_for_reference(jet),
            ),
            LeaderView::Robot { state, dv } => (
                LeaderMotion::of_robot(&state, dv),
                placement.offset_for_robot(state.v, state.omega),
            ),
            LeaderView::Motion {
                motion,
                speed,
                turn_rate,
            } => (motion, placement.offset_for_robot(speed, turn_rate)),
        }
    }
}

/// One evaluation of an agent's controller.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Follow {
    /// `u`, `e` (eq. 7), `z` (eq. 10) of the sensed state.
    pub law: LawOutput,
    /// The leader motion used.
    pub leader: LeaderMotion,
    /// The offsets used.
    pub offset: Offset,
    /// For a velocity base, the kinematic law's `(v*, ω*)` before the base's
    /// limits; `law.u` is then zero and `law.e`, `law.z` are the kinematic
    /// law's ([`crate::kinematic::KinematicOutput`]).
    pub velocity: Option<VelocityCommand>,
}

impl Follow {
    /// The law's command: `(v*, ω*)` for a velocity base, `u` otherwise.
    #[inline]
    pub fn command(&self) -> Command {
        match self.velocity {
            Some(c) => Command::Velocity(c),
            None => Command::Torque(self.law.u),
        }
    }
}

/// The law of agent `spec` in `sensed` state behind `leader`: eqs. 7–13 for a
/// torque-driven robot, the kinematic law for a velocity base. A robot leader
/// on a velocity base is seen at the speeds its base moves at
/// ([`crate::base::VelocityBase::speeds`]): the caller puts them in its state.
#[inline]
pub fn follow(spec: &AgentSpec, sensed: &State, leader: LeaderView<'_>) -> Follow {
    let (motion, offset) = leader.resolve(&spec.placement());
    match spec.drive() {
        Drive::Torque { robot, variant } => Follow {
            law: law(robot, sensed, &motion, &offset, spec.gains(), *variant),
            leader: motion,
            offset,
            velocity: None,
        },
        Drive::Velocity(_) => {
            let k = kinematic_law(sensed, &motion, &offset, spec.gains().ke());
            Follow {
                law: LawOutput {
                    u: Input::default(),
                    e: k.e,
                    z: k.z,
                },
                leader: motion,
                offset,
                velocity: Some(k.cmd),
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::control::{Gains, Variant};
    use crate::formation::Leader;
    use crate::lycomp::{LyComp, LyDerivatives, PlacementSpec};
    use crate::model::RobotParams;
    use crate::reference::{Circle, Order, Trajectory};

    fn spec() -> AgentSpec {
        AgentSpec::new(
            "a",
            RobotParams::AGENT1,
            Leader::Reference,
            Placement::new(PlacementSpec {
                lx_off: 0.3,
                ly_off: 0.35,
                l: 0.1,
                comp: LyComp::Exact,
                derivatives: LyDerivatives::Neglect,
            })
            .expect("valid placement"),
            Gains::PAPER,
            Variant::Complete,
            State::at_rest(0.0, 0.0, 0.0),
        )
        .expect("valid agent")
    }

    #[test]
    fn a_robot_leader_is_the_same_as_its_motion_and_speeds() {
        let s = spec();
        let leader = State {
            x: 1.0,
            y: -0.5,
            theta: 0.4,
            v: 0.3,
            omega: 0.2,
        };
        let me = State::at_rest(0.2, 0.1, 0.3);
        let a = follow(
            &s,
            &me,
            LeaderView::Robot {
                state: leader,
                dv: 0.05,
            },
        );
        let b = follow(
            &s,
            &me,
            LeaderView::Motion {
                motion: LeaderMotion::of_robot(&leader, 0.05),
                speed: 0.3,
                turn_rate: 0.2,
            },
        );
        assert_eq!(a, b);
        assert_eq!(a.leader.p, [1.0, -0.5]);
        // L_Y = L_Yoff + L_Ycomp > L_Yoff for a left turn (eq. 5).
        assert!(a.offset.ly > 0.35 && (a.offset.lx - 0.4).abs() < 1e-15);
    }

    #[test]
    fn a_reference_leader_with_neglected_derivatives_is_its_motion() {
        let s = spec();
        let c = Circle::new([0.0, 0.0], 0.0, 0.2, 0.2).unwrap();
        let jet = c.eval(3.0, Order::Two);
        let me = State::at_rest(-0.3, 0.2, 0.1);
        let a = follow(&s, &me, LeaderView::Reference(&jet));
        let b = follow(
            &s,
            &me,
            LeaderView::Motion {
                motion: LeaderMotion::of_jet(&jet),
                speed: jet.speed(),
                turn_rate: jet.turn_rate(),
            },
        );
        assert_eq!(a, b);
        assert_eq!(
            a.law,
            law(
                &RobotParams::AGENT1,
                &me,
                &a.leader,
                &a.offset,
                s.gains(),
                Variant::Complete
            )
        );
    }
}
