//! Dense encounters as scenarios: `N` robots of one formation swap slots
//! across a circle (the antipodal swap, or any permutation), every one
//! crossing the crowd in the middle — the liveness cases of the safety
//! filter (docs/safety.md, "Everyone gets home").
//!
//! Every robot follows a slow line reference (`leader = "reference"`); its
//! slot is held in the reference's frame (`offset = { x, y, frame =
//! "leader" }`, docs/control-law.md "Offsets in the leader's frame") and lies
//! where another robot starts. At the start every robot faces along the
//! reference with its point `L` ahead on a circle whose centre is
//! `circle + 1` m behind the reference. [`Swap::toml`] writes the scenario
//! (the simulator's; a fleet adds its `[fleet]` section), [`Swap::bound`]
//! the time by which everyone is home.

use std::f64::consts::PI;

/// Every robot's point ahead of its axle, m.
pub const L: f64 = 0.05;

/// Home: `‖e‖` below this, m.
pub const SETTLED: f64 = 0.01;

/// The drive of every robot of a swap.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SwapDrive {
    /// An ideal velocity base (0.5 m/s, 3 rad/s) under the kinematic law,
    /// `ke = 1`, simulated at 10 ms.
    Velocity,
    /// Table I's agent 1 (eq. 3) under the complete law, `ke = 1.5`,
    /// `kz = 10`, simulated at 5 ms.
    Torque,
}

/// The frame every robot's offset is written in.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SwapFrame {
    /// `frame = "leader"`: the slot is fixed in the reference's frame.
    Leader,
    /// The paper's (eq. 7): the slot turns with the follower's heading, so
    /// it lies across the circle only while the robot faces along the
    /// reference.
    Follower,
}

/// One encounter.
#[derive(Debug, Clone, PartialEq)]
pub struct Swap {
    /// The robots' drive.
    pub drive: SwapDrive,
    /// Robot `i` goes to robot `to[i]`'s start (a permutation of `0..N`).
    pub to: Vec<usize>,
    /// The circle's radius, m.
    pub circle: f64,
    /// The safety radius between the robots' points, m.
    pub radius: f64,
    /// The reference's speed, m/s (> 0: a slot in the leader's frame needs
    /// a leader that keeps moving).
    pub speed: f64,
    /// The reference's heading, rad.
    pub heading: f64,
    /// The frame of the offsets.
    pub frame: SwapFrame,
}

impl Swap {
    /// The antipodal swap of `n` robots: robot `i` goes to `i + n/2`.
    pub fn antipodal(drive: SwapDrive, n: usize, circle: f64, radius: f64, speed: f64) -> Swap {
        Swap {
            drive,
            to: (0..n).map(|i| (i + n / 2) % n).collect(),
            circle,
            radius,
            speed,
            heading: 0.0,
            frame: SwapFrame::Leader,
        }
    }

    /// The smallest circle `n` robots fit on with a diameter each around
    /// it and 10 % to spare, m.
    pub fn smallest_circle(n: usize, radius: f64) -> f64 {
        1.1 * n as f64 * 2.0 * radius / (2.0 * PI)
    }

    /// The number of robots.
    pub fn n(&self) -> usize {
        self.to.len()
    }

    /// Robot `i`'s start (its point `L` ahead) in the reference's frame at
    /// `t = 0` (x ahead, y left).
    pub fn at(&self, i: usize) -> [f64; 2] {
        let (s, c) = (2.0 * PI * i as f64 / self.n() as f64).sin_cos();
        [-(self.circle + 1.0) + self.circle * c, self.circle * s]
    }

    /// The farthest a robot's slot lies from its start, m.
    pub fn farthest(&self) -> f64 {
        (0..self.n())
            .map(|i| {
                let (a, b) = (self.at(i), self.at(self.to[i]));
                (a[0] - b[0]).hypot(a[1] - b[1])
            })
            .fold(0.0, f64::max)
    }

    /// The time by which every robot is home (`‖e‖ < SETTLED`), s:
    ///
    /// ```text
    /// T = farthest / s + ln(s / (k SETTLED)) / k + N · 2 radius / s + 20 s
    /// ```
    ///
    /// with `s = 0.15 m/s` the point speed the law keeps to across the
    /// crowd (the filter's `γ` times the gaps it sees: robots within a few
    /// radii of each other close at ~0.1–0.2 m/s) and `k = 1/s` its gain: a
    /// free robot's run and its exponential approach, a robot's diameter of
    /// detour per robot it may have to go round, and 20 s for the deadlock
    /// monitor and the turns. Linear in the circle's size and in `N`.
    pub fn bound(&self) -> f64 {
        let s = 0.15;
        let k = 1.0;
        self.farthest() / s
            + (s / (k * SETTLED)).ln() / k
            + self.n() as f64 * 2.0 * self.radius / s
            + 20.0
    }

    /// The run's length: the bound and 10 s to show the robots stay, s.
    pub fn duration(&self) -> f64 {
        (self.bound() + 10.0).ceil()
    }

    /// The scenario: `[sim]`, `[control]`, one robot type `r`, `[log]` at
    /// 50 ms, the line reference, `[safety]` (`gain = 1`) and the agents.
    pub fn toml(&self) -> String {
        let mut s = String::from("name = \"swap\"\n");
        match self.drive {
            SwapDrive::Velocity => {
                s += &format!("[sim]\nduration = {}\ndt = 0.01\n", self.duration());
                s += &format!(
                    "[control]\nlaw = \"kinematic\"\nke = 1.0\nl = {L}\nlycomp = \"none\"\n"
                );
                s += "[robots.r]\ndrive = \"velocity\"\npreset = \"ideal\"\nv_max = 0.5\nomega_max = 3.0\n";
            }
            SwapDrive::Torque => {
                s += &format!("[sim]\nduration = {}\ndt = 0.005\n", self.duration());
                s += &format!(
                    "[control]\nlaw = \"complete\"\nke = 1.5\nkz = 10.0\nl = {L}\nlycomp = \"none\"\n"
                );
                s += "[robots.r]\npreset = \"agent1\"\n";
            }
        }
        s += "[log]\ndt = 0.05\n";
        s += &format!(
            "[reference.line]\nspeed = {}\nstart = {{ x = 0.0, y = 0.0, theta = {} }}\n",
            self.speed, self.heading
        );
        s += &format!("[safety]\nradius = {}\ngain = 1.0\n", self.radius);
        let frame = match self.frame {
            SwapFrame::Leader => ", frame = \"leader\"",
            SwapFrame::Follower => "",
        };
        let (sin, cos) = self.heading.sin_cos();
        for i in 0..self.n() {
            let p = self.at(i);
            let w = [p[0] * cos - p[1] * sin, p[0] * sin + p[1] * cos];
            // The slot: the point `−offset` from the reference, in its
            // frame (in the follower's: while it faces along the reference).
            let g = self.at(self.to[i]);
            s += &format!(
                "[[agents]]\nrobot = \"r\"\nstart = {{ x = {}, y = {}, theta = {} }}\nleader = \"reference\"\noffset = {{ x = {}, y = {}{frame} }}\n",
                w[0] - L * cos,
                w[1] - L * sin,
                self.heading,
                -g[0],
                -g[1],
            );
        }
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scenario::{Overrides, Scenario};

    /// Every robot starts with its point on the circle, facing along the
    /// reference, and its slot is another robot's start: at `t = 0` the
    /// tracking error of robot `i` is the distance from its start to its
    /// slot, in both frames.
    #[test]
    fn a_swap_puts_each_slot_on_another_start() {
        for frame in [SwapFrame::Leader, SwapFrame::Follower] {
            let mut swap = Swap::antipodal(SwapDrive::Velocity, 6, 1.0, 0.2, 0.05);
            swap.heading = 0.7;
            swap.frame = frame;
            let run = Scenario::parse(&swap.toml(), "swap.toml", None)
                .unwrap()
                .build(&Overrides::default())
                .unwrap();
            let mut sim = run.simulation();
            let frame0 = sim.frame();
            for i in 0..swap.n() {
                let e = frame0.outputs[i].e;
                let (a, b) = (swap.at(i), swap.at(swap.to[i]));
                let want = (a[0] - b[0]).hypot(a[1] - b[1]);
                assert!((e[0].hypot(e[1]) - want).abs() < 1e-9, "{frame:?} {i}");
            }
        }
    }

    /// What holds the paper's frame only refuses slots in the leader's
    /// frame, naming the agent: the batch engine (its kernels hold eq. 7;
    /// the velocity engine packs its members the same way) and the learning
    /// environments.
    #[test]
    fn the_batch_engine_and_the_environments_refuse_the_leaders_frame() {
        for drive in [SwapDrive::Velocity, SwapDrive::Torque] {
            // Without the filter: the engine refuses filters first.
            let text = Swap::antipodal(drive, 4, 1.0, 0.2, 0.05).toml();
            let cut = text.find("[safety]").unwrap();
            let end = cut + text[cut..].find("[[agents]]").unwrap();
            let plain = format!("{}{}", &text[..cut], &text[end..]);
            let run = Scenario::parse(&plain, "swap.toml", None)
                .unwrap()
                .build(&Overrides::default())
                .unwrap();
            if drive == SwapDrive::Torque {
                let e = crate::engine::Engine::from_plan(&run.plan)
                    .err()
                    .unwrap()
                    .to_string();
                assert!(e.contains("leader's frame (agent 1"), "{e}");
            }
            let e = crate::learn::FixedEpisode::of_plan(&run.plan)
                .err()
                .unwrap()
                .to_string();
            assert!(e.contains("leader's frame"), "{drive:?}: {e}");
        }
    }

    /// A slot in the leader's frame behind a reference that stands still
    /// at times (here a line at speed 0) is refused at the agent's
    /// `offset.frame`: it would have no heading there.
    #[test]
    fn a_reference_at_rest_gives_no_frame() {
        let mut swap = Swap::antipodal(SwapDrive::Velocity, 4, 1.0, 0.2, 0.05);
        swap.speed = 0.0;
        let e = Scenario::parse(&swap.toml(), "swap.toml", None)
            .unwrap()
            .build(&Overrides::default())
            .err()
            .unwrap()
            .to_string();
        assert!(
            e.contains("swap.toml") && e.contains("agents[1].offset.frame"),
            "{e}"
        );
        assert!(e.contains("stands still"), "{e}");
    }
}
