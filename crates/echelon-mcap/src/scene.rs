//! The 3D channels: Foxglove's well-known schemas (`foxglove.FrameTransforms`,
//! `foxglove.SceneUpdate`, protobuf) from the official `foxglove` crate, so
//! that Foxglove's (or Lichtblick's) 3D panel draws a run, recorded or live.
//!
//! | topic | schema | content |
//! |---|---|---|
//! | [`TF_TOPIC`] `/tf` | `foxglove.FrameTransforms` | `world` → `robotK/base_link` (REP 105's base frame, namespaced per robot like its ROS topics) |
//! | [`SCENE_TOPIC`] `/scene` | `foxglove.SceneUpdate` | per robot: its body and heading, its slot, the link to its leader, its safety circle |
//! | [`SCENE_STATIC_TOPIC`] `/scene/static` | `foxglove.SceneUpdate` | what does not move: the reference path and the obstacles |
//!
//! One `/tf` and one `/scene` message per robot and instant (a fleet's robots
//! report one at a time); entities have no lifetime, so each robot's replace
//! its previous ones (same ids). Everything is in the `world` frame (the
//! scenario's plane at z = 0), SI units.
//!
//! The slot is where the robot would stand with zero tracking error: from
//! eq. 7, `e = R(θ)(p − p_d) + L`, so `p_slot = p − R(θ)ᵀ e` (equal to
//! `p_d − R(θ)ᵀ L`). The leader link runs from `p` to `p_d` (the reference's
//! point, or the leader robot's position).

use std::io::{Seek, Write};

use echelon::formation::Leader;
use echelon::plan::Plan;
use echelon::reference::{Order, Trajectory};
use echelon::sample::AgentSample;
use foxglove::Encode;
use foxglove::messages::{
    ArrowPrimitive, Color, CylinderPrimitive, FrameTransform, FrameTransforms, LinePrimitive,
    Point3, Pose, Quaternion, SceneEntity, SceneUpdate, SpherePrimitive, TextPrimitive, Timestamp,
    Vector3, line_primitive,
};

use super::{McapLog, McapLogError};

/// Topic of the frame transforms `world` → each robot's `base_link`.
pub const TF_TOPIC: &str = "/tf";
/// Topic of the moving scene (robots, slots, leader links, safety circles).
pub const SCENE_TOPIC: &str = "/scene";
/// Topic of the fixed scene (reference path, obstacles).
pub const SCENE_STATIC_TOPIC: &str = "/scene/static";
/// The fixed frame every pose is given in.
pub const WORLD_FRAME: &str = "world";

/// Radius of a robot's drawn body, m (a display size: the scenario gives
/// wheel geometry, not a footprint).
pub const BODY_RADIUS: f64 = 0.08;
/// Points of the drawn reference path, at most.
const PATH_POINTS: usize = 400;

/// Robot `k`'s (from 1) base frame: `robotK/base_link`.
pub fn base_link(k: u32) -> String {
    format!("robot{k}/base_link")
}

/// A time in seconds as a Foxglove timestamp (negative and non-finite as 0).
pub fn timestamp(t: f64) -> Timestamp {
    let ns = super::nanos(t);
    Timestamp::new(
        (ns / 1_000_000_000).min(u64::from(u32::MAX)) as u32,
        (ns % 1_000_000_000) as u32,
    )
}

/// The rotation by `theta` about z.
fn yaw(theta: f64) -> Quaternion {
    let (s, c) = (0.5 * theta).sin_cos();
    Quaternion {
        x: 0.0,
        y: 0.0,
        z: s,
        w: c,
    }
}

fn pose(x: f64, y: f64, z: f64, theta: f64) -> Pose {
    Pose {
        position: Some(Vector3 { x, y, z }),
        orientation: Some(yaw(theta)),
    }
}

/// An upright cylinder of `diameter` and `height` centred at `(x, y, z)`.
fn cylinder(x: f64, y: f64, z: f64, diameter: f64, height: f64, color: Color) -> CylinderPrimitive {
    CylinderPrimitive {
        pose: Some(pose(x, y, z, 0.0)),
        size: Some(Vector3 {
            x: diameter,
            y: diameter,
            z: height,
        }),
        bottom_scale: 1.0,
        top_scale: 1.0,
        color: Some(color),
    }
}

const fn rgba(r: f64, g: f64, b: f64, a: f64) -> Color {
    Color { r, g, b, a }
}

/// What robot `k` shows at one instant.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ScenePose {
    /// Time, s.
    pub t: f64,
    /// Position, m.
    pub p: [f64; 2],
    /// Heading θ, rad.
    pub theta: f64,
    /// Tracking error `e` (eq. 7), body frame, m.
    pub e: [f64; 2],
    /// The leader's point `p_d`, m.
    pub leader: [f64; 2],
}

impl ScenePose {
    /// The pose of `sample`, following a leader at `p_d = leader`.
    pub fn of(sample: &AgentSample, leader: [f64; 2]) -> ScenePose {
        ScenePose {
            t: sample.t,
            p: [sample.x, sample.y],
            theta: sample.theta,
            e: [sample.ex, sample.ey],
            leader,
        }
    }

    /// The slot `p − R(θ)ᵀ e` (eq. 7 solved for zero error).
    pub fn slot(&self) -> [f64; 2] {
        let (s, c) = self.theta.sin_cos();
        let [ex, ey] = self.e;
        [self.p[0] - (c * ex - s * ey), self.p[1] - (s * ex + c * ey)]
    }
}

/// What is fixed during a run: safety radius, each agent's `L`, obstacles,
/// the reference path, and who follows whom (for [`Scene::leader_point`]).
#[derive(Debug, Clone, PartialEq)]
pub struct SceneSpec {
    /// Each agent's leader (from 0).
    pub leaders: Vec<Leader>,
    /// Each agent's `L` (from 0), m: its point ahead, which the safety
    /// filter keeps `safety_radius` from the others' (the dashboard draws it).
    pub l: Vec<f64>,
    /// The safety filter's radius, m (none: no safety circles).
    pub safety_radius: Option<f64>,
    /// Obstacles `[x, y, r]`, m.
    pub obstacles: Vec<[f64; 3]>,
    /// The reference path `p_d(t)` over the run, m.
    pub path: Vec<[f64; 2]>,
}

impl SceneSpec {
    /// The scene of `plan`: its formation, safety radius, obstacles, and its
    /// reference sampled at up to `PATH_POINTS` (400) instants over the run.
    pub fn of(plan: &Plan) -> SceneSpec {
        let duration = plan.config().duration;
        let n = PATH_POINTS
            .min((duration / plan.config().dt).ceil() as usize + 1)
            .max(2);
        let path = (0..n)
            .map(|i| {
                let t = duration * i as f64 / (n - 1) as f64;
                plan.reference().eval(t, Order::Two).p
            })
            .collect();
        SceneSpec {
            leaders: plan.formation().leaders().to_vec(),
            l: plan.agents().iter().map(|a| a.placement().l()).collect(),
            safety_radius: plan.safety_radius(),
            obstacles: plan
                .obstacles()
                .iter()
                .map(|o| [o.x(), o.y(), o.r()])
                .collect(),
            path,
        }
    }
}

/// The 3D messages of a run, kept and refilled in place (no allocation per
/// instant once built): per robot a one-transform `FrameTransforms` and a
/// `SceneUpdate` of its entities, and the fixed scene.
#[derive(Debug, Clone)]
pub struct Scene {
    tf: Vec<FrameTransforms>,
    robots: Vec<SceneUpdate>,
    fixed: SceneUpdate,
    leaders: Vec<Leader>,
}

/// Entities of a robot's update, in order.
const BODY: usize = 0;
const SLOT: usize = 1;
const LINK: usize = 2;
const SAFETY: usize = 3;

fn entity(id: String, metadata: Vec<foxglove::messages::KeyValuePair>) -> SceneEntity {
    SceneEntity {
        frame_id: WORLD_FRAME.to_owned(),
        id,
        metadata,
        ..SceneEntity::default()
    }
}

/// Robot `k`'s colour: hues spread by the golden ratio.
fn palette(k: usize) -> Color {
    let h = (k as f64 * 0.618_034).fract() * std::f64::consts::TAU;
    rgba(
        0.5 + 0.4 * h.cos(),
        0.5 + 0.4 * (h + 2.094).cos(),
        0.5 + 0.4 * (h + 4.189).cos(),
        1.0,
    )
}

/// Robot `k`'s (from 1) transform `world` → `robotK/base_link`, at the origin.
fn robot_tf(k: u32) -> FrameTransforms {
    FrameTransforms {
        transforms: vec![FrameTransform {
            timestamp: Some(timestamp(0.0)),
            parent_frame_id: WORLD_FRAME.to_owned(),
            child_frame_id: base_link(k),
            translation: Some(Vector3::default()),
            rotation: Some(yaw(0.0)),
        }],
    }
}

/// Robot `k`'s (from 1) body: a cylinder, a heading arrow and its number,
/// with its agent and leader as metadata.
fn robot_body(k: usize, leader: Leader, color: Color) -> SceneEntity {
    let kv = |key: &str, value: String| foxglove::messages::KeyValuePair {
        key: key.to_owned(),
        value,
    };
    let leader = match leader {
        Leader::Reference => "reference".to_owned(),
        Leader::Agent(j) => format!("robot{}", j + 1),
    };
    let mut body = entity(
        format!("robot{k}"),
        vec![kv("agent", k.to_string()), kv("leader", leader)],
    );
    body.cylinders = vec![cylinder(0.0, 0.0, 0.025, 2.0 * BODY_RADIUS, 0.05, color)];
    body.arrows = vec![ArrowPrimitive {
        pose: Some(pose(0.0, 0.0, 0.06, 0.0)),
        shaft_length: 1.5 * BODY_RADIUS,
        shaft_diameter: 0.02,
        head_length: 0.06,
        head_diameter: 0.05,
        color: Some(rgba(0.1, 0.1, 0.1, 1.0)),
    }];
    body.texts = vec![TextPrimitive {
        pose: Some(pose(0.0, 0.0, 0.2, 0.0)),
        billboard: true,
        font_size: 14.0,
        scale_invariant: true,
        color: Some(rgba(0.1, 0.1, 0.1, 1.0)),
        text: k.to_string(),
    }];
    body
}

/// Robot `k`'s (from 1) slot: a small translucent sphere of its colour.
fn robot_slot(k: usize, color: Color) -> SceneEntity {
    let mut slot = entity(format!("robot{k}/slot"), Vec::new());
    slot.spheres = vec![SpherePrimitive {
        pose: Some(pose(0.0, 0.0, 0.0, 0.0)),
        size: Some(Vector3 {
            x: 0.05,
            y: 0.05,
            z: 0.05,
        }),
        color: Some(Color { a: 0.5, ..color }),
    }];
    slot
}

/// Robot `k`'s (from 1) link to its leader: one grey segment.
fn robot_link(k: usize) -> SceneEntity {
    let mut link = entity(format!("robot{k}/link"), Vec::new());
    link.lines = vec![LinePrimitive {
        r#type: line_primitive::Type::LineList as i32,
        pose: Some(pose(0.0, 0.0, 0.0, 0.0)),
        thickness: 2.0,
        scale_invariant: true,
        points: vec![Point3::default(), Point3::default()],
        color: Some(rgba(0.4, 0.4, 0.4, 0.8)),
        ..LinePrimitive::default()
    }];
    link
}

/// Robot `k`'s (from 1) update: body, slot, link, and its safety circle of
/// radius `safety_radius` if any.
fn robot_update(k: usize, leader: Leader, safety_radius: Option<f64>) -> SceneUpdate {
    let color = palette(k);
    let mut entities = vec![
        robot_body(k, leader, color),
        robot_slot(k, color),
        robot_link(k),
    ];
    if let Some(r) = safety_radius {
        let mut safety = entity(format!("robot{k}/safety"), Vec::new());
        let red = rgba(0.9, 0.2, 0.2, 0.15);
        safety.cylinders = vec![cylinder(0.0, 0.0, 0.001, 2.0 * r, 0.002, red)];
        entities.push(safety);
    }
    SceneUpdate {
        deletions: Vec::new(),
        entities,
    }
}

/// The fixed scene of `spec`: the reference path, then the obstacles.
fn fixed_update(spec: &SceneSpec) -> SceneUpdate {
    let mut path = entity("reference".to_owned(), Vec::new());
    path.lines = vec![LinePrimitive {
        r#type: line_primitive::Type::LineStrip as i32,
        pose: Some(pose(0.0, 0.0, 0.0, 0.0)),
        thickness: 1.5,
        scale_invariant: true,
        points: spec
            .path
            .iter()
            .map(|&[x, y]| Point3 { x, y, z: 0.0 })
            .collect(),
        color: Some(rgba(0.2, 0.4, 0.9, 0.8)),
        ..LinePrimitive::default()
    }];
    let mut fixed = vec![path];
    for (i, &[x, y, r]) in spec.obstacles.iter().enumerate() {
        let mut o = entity(format!("obstacle/{}", i + 1), Vec::new());
        o.cylinders = vec![cylinder(x, y, 0.1, 2.0 * r, 0.2, rgba(0.3, 0.3, 0.3, 0.9))];
        fixed.push(o);
    }
    SceneUpdate {
        deletions: Vec::new(),
        entities: fixed,
    }
}

impl Scene {
    /// The scene of `spec`'s robots (none moved yet: all at the origin).
    pub fn new(spec: &SceneSpec) -> Scene {
        let n = spec.leaders.len();
        let tf = (1..=n as u32).map(robot_tf).collect();
        let robots = (1..=n)
            .map(|k| robot_update(k, spec.leaders[k - 1], spec.safety_radius))
            .collect();
        Scene {
            tf,
            robots,
            fixed: fixed_update(spec),
            leaders: spec.leaders.clone(),
        }
    }

    /// Number of robots.
    pub fn robots(&self) -> usize {
        self.robots.len()
    }

    /// The leader's point `p_d` of agent `i` (from 0) when the robots stand
    /// at `positions` and the reference at `reference_point`.
    pub fn leader_point(&self, i: usize, positions: &[[f64; 2]], reference: [f64; 2]) -> [f64; 2] {
        match self.leaders.get(i) {
            Some(Leader::Agent(j)) => positions.get(*j).copied().unwrap_or(reference),
            _ => reference,
        }
    }

    /// Moves robot `k` (from 1) to `pose`; `None` if there is no robot `k`.
    pub fn set(&mut self, k: u32, at: &ScenePose) -> Option<()> {
        let i = (k as usize).checked_sub(1)?;
        let stamp = Some(timestamp(at.t));
        let tf = &mut self.tf.get_mut(i)?.transforms[0];
        tf.timestamp = stamp;
        tf.translation = Some(Vector3 {
            x: at.p[0],
            y: at.p[1],
            z: 0.0,
        });
        tf.rotation = Some(yaw(at.theta));
        let update = self.robots.get_mut(i)?;
        for e in &mut update.entities {
            e.timestamp = stamp;
        }
        let [x, y] = at.p;
        let e = &mut update.entities;
        e[BODY].cylinders[0].pose = Some(pose(x, y, 0.025, at.theta));
        e[BODY].arrows[0].pose = Some(pose(x, y, 0.06, at.theta));
        e[BODY].texts[0].pose = Some(pose(x, y, 0.2, 0.0));
        let [sx, sy] = at.slot();
        e[SLOT].spheres[0].pose = Some(pose(sx, sy, 0.0, 0.0));
        let points = &mut e[LINK].lines[0].points;
        points[0] = Point3 { x, y, z: 0.0 };
        points[1] = Point3 {
            x: at.leader[0],
            y: at.leader[1],
            z: 0.0,
        };
        if let Some(safety) = e.get_mut(SAFETY) {
            safety.cylinders[0].pose = Some(pose(x, y, 0.001, 0.0));
        }
        Some(())
    }

    /// Robot `k`'s (from 1) transform and scene, as last [`Scene::set`].
    pub fn robot(&self, k: u32) -> Option<(&FrameTransforms, &SceneUpdate)> {
        let i = (k as usize).checked_sub(1)?;
        Some((self.tf.get(i)?, self.robots.get(i)?))
    }

    /// The fixed scene (reference path, obstacles), stamped `t`.
    pub fn fixed(&mut self, t: f64) -> &SceneUpdate {
        for e in &mut self.fixed.entities {
            e.timestamp = Some(timestamp(t));
        }
        &self.fixed
    }
}

/// The MCAP channels of the 3D topics in one log, and a buffer to encode into.
#[derive(Debug, Default)]
pub struct SceneChannels {
    tf: u16,
    scene: u16,
    fixed: u16,
    seq: [u32; 3],
    buf: Vec<u8>,
}

impl SceneChannels {
    /// Registers [`TF_TOPIC`], [`SCENE_TOPIC`] and [`SCENE_STATIC_TOPIC`] in `log`.
    pub fn register<W: Write + Seek>(log: &mut McapLog<W>) -> Result<Self, McapLogError> {
        Ok(SceneChannels {
            tf: log.foxglove_channel::<FrameTransforms>(TF_TOPIC)?,
            scene: log.foxglove_channel::<SceneUpdate>(SCENE_TOPIC)?,
            fixed: log.foxglove_channel::<SceneUpdate>(SCENE_STATIC_TOPIC)?,
            seq: [0; 3],
            buf: Vec::with_capacity(4096),
        })
    }

    fn write<W: Write + Seek, T: Encode>(
        &mut self,
        log: &mut McapLog<W>,
        which: usize,
        log_time: u64,
        publish_time: u64,
        msg: &T,
    ) -> Result<(), McapLogError> {
        let channel = [self.tf, self.scene, self.fixed][which];
        self.buf.clear();
        msg.encode(&mut self.buf)
            .map_err(|e| McapLogError::Encode(e.to_string()))?;
        let seq = self.seq[which];
        self.seq[which] = seq.wrapping_add(1);
        log.write(channel, seq, log_time, publish_time, &self.buf)
    }

    /// Writes robot `k`'s transform and scene as `scene` holds them.
    pub fn robot<W: Write + Seek>(
        &mut self,
        log: &mut McapLog<W>,
        scene: &Scene,
        k: u32,
        log_time: u64,
        publish_time: u64,
    ) -> Result<(), McapLogError> {
        let (tf, update) = scene
            .robot(k)
            .ok_or_else(|| McapLogError::Encode(format!("no robot {k} in the scene")))?;
        self.write(log, 0, log_time, publish_time, tf)?;
        self.write(log, 1, log_time, publish_time, update)
    }

    /// Writes the fixed scene, stamped `t`.
    pub fn fixed<W: Write + Seek>(
        &mut self,
        log: &mut McapLog<W>,
        scene: &mut Scene,
        t: f64,
        log_time: u64,
    ) -> Result<(), McapLogError> {
        let publish_time = super::nanos(t);
        let fixed = scene.fixed(t);
        self.write(log, 2, log_time, publish_time, fixed)
    }
}

#[cfg(test)]
mod tests;
