//! One agent's law evaluation, shared by the simulator
//! ([`crate::sim::Simulation`]) and the fleet's robot process: from what the
//! agent knows of its leader to the leader motion `p_d, ṗ_d, p̈_d`, the offsets
//! `L_X, L_Y` (eqs. 4–6) and the law's output (eq. 13).

use crate::formation::agent::{AgentSpec, Command, Drive};
use crate::law::control::{LawOutput, LeaderMotion, Offset, law};
use crate::law::kinematic::kinematic_law;
use crate::law::lycomp::{OffsetFrame, Placement};
use crate::model::Input;
use crate::model::State;
use crate::model::base::VelocityCommand;
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
        /// `θ_d`, rad: the direction of `ṗ_d`, kept by whoever advanced
        /// the sample when it comes to rest (a leader stopped by a link-loss
        /// policy keeps the heading it had).
        heading: f64,
    },
}

impl LeaderView<'_> {
    /// The leader motion and the offsets `L_X, L_Y, L̇_Y, L̈_Y` (eqs. 4–6) a
    /// follower with `placement` holds it at.
    ///
    /// A slot in the leader's frame ([`crate::law::lycomp::OffsetFrame::Leader`])
    /// turns with the leader's heading: the reference's path heading, turn
    /// rate and angular acceleration ([`Jet::frame`]); a leader robot's `θ`
    /// and `ω` (its `ω̇` neglected, as `L̇_Y` is for robot leaders); a
    /// leader known by its motion: its `θ_d` and `ω_d` (`ω̇` neglected:
    /// exact on the circle and the line the fleet predicts along).
    #[inline]
    pub fn resolve(&self, placement: &Placement) -> (LeaderMotion, Offset) {
        let (motion, offset) = self.resolve_follower(placement);
        if placement.frame() == OffsetFrame::Follower {
            return (motion, offset);
        }
        let (theta, omega, domega) = match *self {
            LeaderView::Reference(jet) => jet.frame(),
            LeaderView::Robot { state, .. } => (state.theta, state.omega, 0.0),
            LeaderView::Motion {
                turn_rate, heading, ..
            } => (heading, turn_rate, 0.0),
        };
        (placement.slot(&motion, theta, omega, domega), offset)
    }

    /// [`LeaderView::resolve`] in the follower's frame (eq. 7).
    #[inline]
    fn resolve_follower(&self, placement: &Placement) -> (LeaderMotion, Offset) {
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
                ..
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
    /// law's ([`crate::law::kinematic::KinematicOutput`]).
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
/// ([`crate::model::base::VelocityBase::speeds`]): the caller puts them in its state.
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
    use crate::formation::Leader;
    use crate::law::control::{Gains, Variant};
    use crate::law::lycomp::{LyComp, LyDerivatives, PlacementSpec};
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
                heading: leader.theta,
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
                heading: jet.heading(),
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

    /// A slot in the leader's frame moves as its formula says: along a
    /// lemniscate (heading, turn rate and angular acceleration all varying)
    /// and a circle, at random offsets and instants, the slot's `q̇` and
    /// `q̈` from [`LeaderView::resolve`] match central differences of its `q`
    /// and `q̇`, the law is pure tracking (`L_X = L`, `L_Y = 0`), and on
    /// the reference itself (zero offset) the slot is the reference.
    mod leader_frame {
        use super::*;
        use crate::reference::{Lemniscate, Reference};
        use proptest::prelude::*;

        fn slot(r: &Reference, p: &Placement, t: f64) -> LeaderMotion {
            LeaderView::Reference(&r.eval(t, Order::Four)).resolve(p).0
        }

        proptest! {
            #[test]
            fn the_slot_moves_as_its_formula_says(
                x in -3.0..3.0f64, y in -3.0..3.0f64, t in 1.0..60.0f64,
                lemniscate in any::<bool>(), c in 0.05..0.3f64, a in 0.5..3.0f64,
            ) {
                let r = if lemniscate {
                    Reference::Lemniscate(Lemniscate::new(a, c, [0.3, -0.2]).unwrap())
                } else {
                    Reference::Circle(Circle::new([0.1, 0.2], 0.4, a * c, c).unwrap())
                };
                let p = Placement::leader_frame(x, y, 0.05).unwrap();
                let (motion, offset) = LeaderView::Reference(&r.eval(t, Order::Four)).resolve(&p);
                prop_assert_eq!((offset.lx, offset.ly, offset.dly), (0.05, 0.0, 0.0));
                let h = 1e-4;
                let (before, after) = (slot(&r, &p, t - h), slot(&r, &p, t + h));
                for k in 0..2 {
                    let dq = (after.p[k] - before.p[k]) / (2.0 * h);
                    let ddq = (after.dp[k] - before.dp[k]) / (2.0 * h);
                    let scale = 1.0 + motion.dp[k].abs() + motion.ddp[k].abs();
                    prop_assert!((dq - motion.dp[k]).abs() < 1e-6 * scale, "q̇ {k}: {dq} vs {}", motion.dp[k]);
                    prop_assert!((ddq - motion.ddp[k]).abs() < 1e-5 * scale, "q̈ {k}: {ddq} vs {}", motion.ddp[k]);
                }
                // The slot is `o` behind and to the right of the leader, in
                // its frame.
                let jet = r.eval(t, Order::Four);
                let (theta, _, _) = jet.frame();
                let (sn, cs) = theta.sin_cos();
                let back = [jet.p[0] - motion.p[0], jet.p[1] - motion.p[1]];
                prop_assert!((cs * back[0] + sn * back[1] - x).abs() < 1e-9);
                prop_assert!((-sn * back[0] + cs * back[1] - y).abs() < 1e-9);
            }
        }

        /// A leader robot's frame is its heading; a leader known by its
        /// motion, the heading it comes with (also at rest). In the
        /// follower's frame nothing moves.
        #[test]
        fn robot_and_motion_leaders_give_their_heading() {
            let p = Placement::leader_frame(1.0, 0.0, 0.05).unwrap();
            let state = State {
                x: 2.0,
                y: 1.0,
                theta: std::f64::consts::FRAC_PI_2,
                v: 0.0,
                omega: 0.0,
            };
            let q = LeaderView::Robot { state, dv: 0.0 }.resolve(&p).0;
            assert!(
                (q.p[0] - 2.0).abs() < 1e-12 && (q.p[1] - 0.0).abs() < 1e-12,
                "{q:?}"
            );
            // At rest, the heading it was given.
            let motion = LeaderMotion {
                p: [0.0, 0.0],
                dp: [0.0, 0.0],
                ddp: [0.0, 0.0],
            };
            let view = LeaderView::Motion {
                motion,
                speed: 0.0,
                turn_rate: 0.0,
                heading: -std::f64::consts::FRAC_PI_2,
            };
            let q = view.resolve(&p).0;
            assert!(
                (q.p[0]).abs() < 1e-12 && (q.p[1] - 1.0).abs() < 1e-12,
                "{q:?}"
            );
            let follower = Placement::new(PlacementSpec {
                lx_off: 1.0,
                ly_off: 0.0,
                l: 0.05,
                comp: LyComp::None,
                derivatives: LyDerivatives::Neglect,
            })
            .unwrap();
            assert_eq!(view.resolve(&follower).0, motion);
        }
    }
}
