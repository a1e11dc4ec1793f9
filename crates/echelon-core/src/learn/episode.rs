//! An episode's draw: the leader's path, the slots, the robots' starts and
//! the obstacles.

use std::f64::consts::PI;

use super::EnvConfig;
use super::env::Robot;
use crate::error::ParamError;
use crate::formation::Leader;
use crate::law::lycomp::{LyComp, OffsetFrame};
use crate::math::rng::SplitMix64;
use crate::model::State;
use crate::reference::{Circle, Order, Reference, Trajectory};
use crate::safety::{Obstacle, point};
use crate::sim::plan::Plan;

/// A seed for stream `k` of `seed`.
pub(super) fn mix(seed: u64, k: u64) -> u64 {
    SplitMix64::new(seed ^ k.wrapping_mul(0x9e37_79b9_7f4a_7c15)).next_u64()
}

/// How far a start may lie from its slot, in spacings.
const START_SPREAD: f64 = 0.2;
/// How far a slot may lie from its lattice point, in spacings.
const SLOT_JITTER: f64 = 0.15;
/// How far a start's heading may differ from the leader's, rad.
const HEADING_SPREAD: f64 = 0.5;

/// Draws an episode into `leader`, `robots` (slots and starts) and
/// `obstacles` from `seed`: the leader a reference of constant speed and
/// turn rate; slots on a lattice `spacing` apart behind the leader (`⌈√N⌉`
/// wide), jittered and shuffled; starts near the slots, at rest, their
/// points at least the radius apart when the draw allows it (20 tries, else
/// the slots); then `config.obstacles` obstacles ([`obstacles`]). The
/// obstacles are drawn last, so that an episode with them has the same
/// leader, slots and starts as the one without.
pub(super) fn draw(
    config: &EnvConfig,
    seed: u64,
    leader: &mut Reference,
    robots: &mut [Robot],
    obstacles: &mut Vec<Obstacle>,
) {
    let mut rng = SplitMix64::new(seed);
    let heading = rng.uniform(-PI, PI);
    let speed = rng.uniform(config.speed.0, config.speed.1);
    let turn = rng.uniform(-config.turn, config.turn);
    let circle = Circle::new([0.0; 2], heading, speed, turn)
        .unwrap_or_else(|_| unreachable!("finite, speed ≥ 0"));
    *leader = Reference::Circle(circle);
    formation(config, &mut rng, heading, robots);
    self::obstacles(config, &mut rng, &circle, robots, obstacles);
}

/// The slots and starts of `robots` behind a leader that starts at the
/// origin facing `heading` (see [`draw`]).
fn formation(config: &EnvConfig, rng: &mut SplitMix64, heading: f64, robots: &mut [Robot]) {
    let n = robots.len();
    let s = config.spacing;
    let width = (n as f64).sqrt().ceil() as usize;
    for (m, r) in robots.iter_mut().enumerate() {
        let (row, col) = (m / width, m % width);
        let behind = (row as f64 + 1.0) * s + SLOT_JITTER * s * rng.uniform(-1.0, 1.0);
        let lateral = (col as f64 - 0.5 * (width as f64 - 1.0)) * s
            + SLOT_JITTER * s * rng.uniform(-1.0, 1.0);
        r.slot = [behind, -lateral];
    }
    // Fisher–Yates: robot i takes slot i after the shuffle.
    for i in (1..n).rev() {
        let j = (rng.next_u64() % (i as u64 + 1)) as usize;
        let (a, b) = (robots[i].slot, robots[j].slot);
        (robots[i].slot, robots[j].slot) = (b, a);
    }
    let (sin, cos) = heading.sin_cos();
    let at_slot = |[lx, ly]: [f64; 2]| {
        State::at_rest(-(lx * cos - ly * sin), -(lx * sin + ly * cos), heading)
    };
    for _ in 0..20 {
        for r in robots.iter_mut() {
            let radius = START_SPREAD * s * rng.next_f64().sqrt();
            let a = rng.uniform(-PI, PI);
            let slot = at_slot(r.slot);
            r.state = State::at_rest(
                slot.x + radius * a.cos(),
                slot.y + radius * a.sin(),
                heading + rng.uniform(-HEADING_SPREAD, HEADING_SPREAD),
            );
        }
        if apart(robots, config.l, config.radius) {
            return;
        }
    }
    for r in robots.iter_mut() {
        r.state = at_slot(r.slot);
    }
}

/// Tries at drawing a place for an obstacle clear of the robots.
const OBSTACLE_TRIES: usize = 20;

/// `config.obstacles` discs into `out` (cleared), radii drawn in
/// `config.obstacle_radius`, each on the leader's path: at the leader's
/// place at a time drawn over the episode (`max_steps · dt`), moved across
/// the path by up to the formation's half-width and a spacing, so that the
/// formation meets them. Each edge is at least the radius from every
/// robot's start point (the filter's constraint holds at the start): a
/// place that is not is drawn again ([`OBSTACLE_TRIES`] tries), then the
/// obstacle goes ahead of the leader's start, beyond every robot.
fn obstacles(
    config: &EnvConfig,
    rng: &mut SplitMix64,
    leader: &Circle,
    robots: &[Robot],
    out: &mut Vec<Obstacle>,
) {
    out.clear();
    if config.obstacles == 0 {
        return;
    }
    let s = config.spacing;
    let width = (robots.len() as f64).sqrt().ceil();
    let half = 0.5 * (width - 1.0) * s + (SLOT_JITTER + 1.0) * s;
    let horizon = config.max_steps as f64 * config.dt;
    let clear = |c: [f64; 2], r: f64| {
        robots.iter().all(|b| {
            let p = point(&b.state, config.l);
            (p[0] - c[0]).hypot(p[1] - c[1]) >= r + config.radius
        })
    };
    // Every start point lies within `far` of the origin.
    let far = robots.iter().fold(0.0f64, |m, b| {
        let p = point(&b.state, config.l);
        m.max(p[0].hypot(p[1]))
    });
    let (lo, hi) = config.obstacle_radius;
    for _ in 0..config.obstacles {
        let r = rng.uniform(lo, hi);
        let mut centre = None;
        for _ in 0..OBSTACLE_TRIES {
            let t = rng.uniform(0.0, horizon);
            let p = leader.eval(t, Order::Two).p;
            let (sin, cos) = (leader.heading() + leader.turn_rate() * t).sin_cos();
            let across = rng.uniform(-half, half);
            let c = [p[0] - across * sin, p[1] + across * cos];
            if clear(c, r) {
                centre = Some(c);
                break;
            }
        }
        let [x, y] = centre.unwrap_or_else(|| {
            let d = far + r + config.radius + s;
            let (sin, cos) = leader.heading().sin_cos();
            [d * cos, d * sin]
        });
        out.push(Obstacle::new(x, y, r).unwrap_or_else(|_| unreachable!("finite, r > 0")));
    }
}

/// Whether every two robots' points are at least `radius` apart.
fn apart(robots: &[Robot], l: f64, radius: f64) -> bool {
    robots.iter().enumerate().all(|(i, a)| {
        let p = point(&a.state, l);
        robots[i + 1..].iter().all(|b| {
            let q = point(&b.state, l);
            (p[0] - q[0]).hypot(p[1] - q[1]) >= radius
        })
    })
}

/// A scenario's formation as every episode's: its reference, each agent's
/// `L_X = L_Xoff + L`, `L_Y = L_Yoff`, its start, and the scenario's
/// obstacles.
#[derive(Debug, Clone)]
pub struct FixedEpisode {
    /// The reference.
    pub leader: Reference,
    /// Each agent's `L_X`, m.
    pub lx: Vec<f64>,
    /// Each agent's `L_Y`, m.
    pub ly: Vec<f64>,
    /// Each agent's start.
    pub starts: Vec<State>,
    /// The obstacles every agent knows (the scenario's `[safety]`).
    pub obstacles: Vec<Obstacle>,
}

/// What a scenario's robots are, for [`super::EnvConfig`]: all velocity
/// bases of one kind, or all torque robots of one kind.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum PlanRobots {
    /// Velocity bases.
    Velocity(crate::model::base::VelocityBase),
    /// Torque-driven robots (eq. 3).
    Torque(crate::model::RobotParams),
}

impl FixedEpisode {
    /// The episode of `plan`, its robots and its agents' `L` (the same for
    /// all), refusing what the environments do not model: an agent that
    /// follows another agent or tracks purely, an `L_Ycomp` (the slot would
    /// move with the leader's turn), robots of different kinds.
    pub fn of_plan(plan: &Plan) -> Result<(FixedEpisode, PlanRobots, f64), ParamError> {
        let agents = plan.agents();
        let refuse = |i: usize, what: &str| {
            ParamError::new(
                "scenario",
                (i + 1) as f64,
                format!("agent {}: {what}", i + 1),
            )
        };
        let mut robots = None;
        let mut l = None;
        let mut episode = FixedEpisode {
            leader: plan.reference().clone(),
            lx: Vec::with_capacity(agents.len()),
            ly: Vec::with_capacity(agents.len()),
            starts: Vec::with_capacity(agents.len()),
            obstacles: plan.obstacles().to_vec(),
        };
        for (i, a) in agents.iter().enumerate() {
            if a.leader() != Leader::Reference {
                return Err(refuse(
                    i,
                    "follows another agent; the environments put every robot behind the reference",
                ));
            }
            let p = a.placement();
            if p.frame() != OffsetFrame::Follower {
                return Err(refuse(
                    i,
                    "holds its offset in the leader's frame; the environments hold the paper's (eq. 7)",
                ));
            }
            if p.lycomp() != LyComp::None {
                return Err(refuse(
                    i,
                    "has an L_Ycomp; the environments hold fixed offsets (lycomp = \"none\")",
                ));
            }
            let kind = match (a.velocity_robot(), a.torque_robot()) {
                (Some(v), _) => PlanRobots::Velocity(v.base()),
                (None, Some(r)) => PlanRobots::Torque(*r),
                (None, None) => return Err(refuse(i, "has no robot the environments model")),
            };
            if robots.is_some_and(|r| r != kind) {
                return Err(refuse(
                    i,
                    "is another kind of robot than agent 1; the environments hold one kind",
                ));
            }
            if l.is_some_and(|l| l != p.l()) {
                return Err(refuse(i, "has another L than agent 1"));
            }
            robots = Some(kind);
            l = Some(p.l());
            episode.lx.push(p.lx());
            episode.ly.push(p.ly_off());
            episode.starts.push(a.start());
        }
        match (robots, l) {
            (Some(r), Some(l)) => Ok((episode, r, l)),
            _ => Err(ParamError::new("scenario", 0.0, "has no agents")),
        }
    }
}
