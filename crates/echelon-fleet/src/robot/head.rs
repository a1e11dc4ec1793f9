//! A driven head (`ros2 = { driven = true }`, docs/ros2.md "A driven robot
//! at the head"): the robot publishes its robot's motion for its followers
//! and commands nothing.

use crate::plant::Plant;
use crate::wire::{LinkStatus, RobotState};

use super::{Robot, RobotTick};

/// Time constant of the derivative filter that gives a driven head's `v̇`,
/// `ω̇` from its odometry's speeds, fleet s ([`HeadFilter`]).
pub const HEAD_FILTER: f64 = 0.1;

/// `v̇`, `ω̇` of a driven head from its measured speeds: the "dirty
/// derivative" `s / (τ s + 1)` with `τ =` [`HEAD_FILTER`], discretised by
/// backward Euler (stable at any step): `x ← x + h/(τ + h) (u − x)`,
/// `u̇ ≈ (u − x)/τ`. A ramp's slope is reached within `e^{−t/τ}`; noise
/// above `1/(2π τ)` ≈ 1.6 Hz is attenuated.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct HeadFilter {
    /// Time of the last update and the filtered `(v, ω)` then.
    last: Option<(f64, [f64; 2])>,
}

impl HeadFilter {
    /// The filter fed speeds `(v, ω)` measured at time `t`: `(v̇, ω̇)`.
    pub fn update(&mut self, t: f64, v: f64, omega: f64) -> (f64, f64) {
        let u = [v, omega];
        let x = match self.last {
            Some((t0, x)) if t > t0 => {
                let a = (t - t0) / (HEAD_FILTER + t - t0);
                [x[0] + a * (u[0] - x[0]), x[1] + a * (u[1] - x[1])]
            }
            Some((_, x)) => x,
            None => u,
        };
        self.last = Some((t, x));
        ((u[0] - x[0]) / HEAD_FILTER, (u[1] - x[1]) / HEAD_FILTER)
    }
}

impl<P: Plant> Robot<P> {
    /// A driven head's tick: its robot's state from the plant (its
    /// odometry, world-mapped and fixed), `v̇`, `ω̇` from [`HeadFilter`],
    /// published as a state its followers follow; nothing commanded.
    /// Stale odometry publishes nothing: the followers' streams go stale
    /// and their link-loss policy applies.
    pub(super) fn tick_driven(&mut self, now: f64) -> RobotTick {
        let now = self.fleet_time(now);
        self.plant.advance(now);
        // Its base's hazards pause the fleet (its followers stop); its
        // driver owns its cmd_vel.
        self.check_hazards(now);
        let publish = self.plant.state().map(|state| {
            let (dv, domega) = self.head.update(now, state.v, state.omega);
            self.last = RobotState {
                t: now,
                agent: self.config.agent,
                link: LinkStatus::Tracking,
                state,
                dv,
                domega,
                sigma: self.plant.position_sigma(),
                ..RobotState::default()
            };
            self.ticks += 1;
            self.header_for(self.last)
        });
        let stats = (now >= self.next_stats).then(|| {
            self.next_stats = now + 1.0;
            self.stats_at(now, LinkStatus::Tracking)
        });
        let done = self.config.duration.is_some_and(|d| now >= d);
        self.next_tick = (self.next_tick + self.config.period).max(now);
        RobotTick {
            publish,
            stats,
            done,
        }
    }
}
