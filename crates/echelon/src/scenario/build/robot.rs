//! A robot's body by name: a `[robots.NAME]` section (torque or velocity
//! base), else a preset.

use crate::base::{VelocityBase, VelocityBaseSpec, VelocityRobot};
use crate::error::ScenarioError;
use crate::model::{RobotParams, RobotParamsSpec};
use crate::scenario::fields::field_names;
use crate::scenario::locate::FieldPath;
use crate::scenario::schema::{DriveName, RobotSection};

use super::Builder;

impl Builder<'_> {
    /// A robot by name: a `[robots.NAME]`, else a preset (torque: `agent1`,
    /// `agent2`; velocity: [`VelocityRobot::PRESETS`]).
    pub(super) fn robot(&self, name: &str, path: &FieldPath) -> Result<Body, ScenarioError> {
        if let Some(r) = self.file.robots.get(name) {
            return self.robot_section(name, r);
        }
        if let Some(p) = RobotParams::preset(name) {
            return Ok(Body::Torque(p));
        }
        VelocityRobot::preset(name)
            .map(Body::Velocity)
            .ok_or_else(|| {
                let mut known: Vec<&str> = RobotParams::PRESETS.iter().map(|(n, _)| *n).collect();
                known.extend(VelocityRobot::PRESETS.iter().map(|(n, _)| *n));
                known.extend(self.file.robots.keys().map(String::as_str));
                self.at.error(
                    path,
                    format!("unknown robot `{name}` (known: {})", known.join(", ")),
                )
            })
    }

    fn robot_section(&self, name: &str, r: &RobotSection) -> Result<Body, ScenarioError> {
        let at = FieldPath::from("robots").key(name);
        let velocity_preset = r.preset.as_deref().and_then(VelocityRobot::preset);
        let drive = r.drive.unwrap_or(if velocity_preset.is_some() {
            DriveName::Velocity
        } else {
            DriveName::Torque
        });
        // A drive takes the fields its robots have: a field given that only
        // the other drive's robots have is refused.
        let torque = field_names(&RobotParams::AGENT1).unwrap_or_default();
        // (the TurtleBot 4's: every field, its reverse_limit included)
        let velocity = field_names(&VelocityRobot::TURTLEBOT4).unwrap_or_default();
        let (takes, foreign, why) = match drive {
            DriveName::Torque => (
                torque,
                velocity,
                "is a velocity base's field: this robot is torque-driven (set drive = \"velocity\")",
            ),
            DriveName::Velocity => (
                velocity,
                torque,
                "is a torque-driven robot's field: a velocity base (drive = \"velocity\") runs its own motor loops and takes lags and limits instead",
            ),
        };
        let given = field_names(r).unwrap_or_default();
        if let Some(key) = given
            .into_iter()
            .find(|key| foreign.contains(key) && !takes.contains(key))
        {
            return Err(self.at.error(&at.key(key), format!("`{key}` {why}")));
        }
        if drive == DriveName::Velocity {
            return self
                .velocity_section(&at, r, velocity_preset)
                .map(Body::Velocity);
        }
        let base = match &r.preset {
            Some(p) => Some(RobotParams::preset(p).ok_or_else(|| {
                self.at.error(
                    &at.key("preset"),
                    format!("unknown preset `{p}` (presets: agent1, agent2)"),
                )
            })?),
            None => None,
        };
        let base = base.map(|b| b.spec());
        // A field given, else the preset's.
        let field = |given: Option<f64>, of: fn(&RobotParamsSpec) -> f64, key: &str| {
            given.or(base.as_ref().map(of)).ok_or_else(|| {
                self.at.error(
                    &at,
                    format!(
                        "missing field `{key}` (or start from a preset with `preset = \"agent1\"`)"
                    ),
                )
            })
        };
        let params = RobotParams::new(RobotParamsSpec {
            mass: field(r.mass, |b| b.mass, "mass")?,
            linear_friction: field(r.linear_friction, |b| b.linear_friction, "linear_friction")?,
            inertia: field(r.inertia, |b| b.inertia, "inertia")?,
            angular_friction: field(
                r.angular_friction,
                |b| b.angular_friction,
                "angular_friction",
            )?,
            half_wheelbase: field(r.half_wheelbase, |b| b.half_wheelbase, "half_wheelbase")?,
            wheel_radius: field(r.wheel_radius, |b| b.wheel_radius, "wheel_radius")?,
            torque_limit: r.torque_limit.or(base.and_then(|b| b.torque_limit)),
        });
        let params = self.within(&at, params)?;
        Ok(Body::Torque(params))
    }

    /// A `[robots.NAME]` with `drive = "velocity"`: a preset's values (or an
    /// ideal base) overridden field by field; an absent limit is no limit.
    fn velocity_section(
        &self,
        at: &FieldPath,
        r: &RobotSection,
        preset: Option<VelocityRobot>,
    ) -> Result<VelocityRobot, ScenarioError> {
        let from = match (&r.preset, preset) {
            (Some(p), None) => {
                let known: Vec<&str> = VelocityRobot::PRESETS.iter().map(|(n, _)| *n).collect();
                return Err(self.at.error(
                    &at.key("preset"),
                    format!(
                        "unknown velocity-base preset `{p}` (presets: {})",
                        known.join(", ")
                    ),
                ));
            }
            (_, Some(p)) => p,
            (None, None) => VelocityRobot::IDEAL,
        };
        let b = from.base().spec();
        let robot = VelocityBase::new(VelocityBaseSpec {
            tau_v: r.tau_v.unwrap_or(b.tau_v),
            tau_omega: r.tau_omega.unwrap_or(b.tau_omega),
            v_max: r.v_max.unwrap_or(b.v_max),
            omega_max: r.omega_max.unwrap_or(b.omega_max),
            a_max: r.a_max.unwrap_or(b.a_max),
            alpha_max: r.alpha_max.unwrap_or(b.alpha_max),
            accel: r.accel.unwrap_or(b.accel),
        })
        .and_then(|base| {
            VelocityRobot::new(
                base,
                r.half_wheelbase.unwrap_or(from.half_wheelbase()),
                r.wheel_radius.unwrap_or(from.wheel_radius()),
            )
        })
        .and_then(|robot| {
            robot.with_reverse_limit(r.reverse_limit.unwrap_or(from.reverse_limit()))
        });
        let robot = self.within(at, robot)?;
        Ok(robot)
    }
}

/// A robot's body as the scenario defines it, before its law is chosen.
#[derive(Debug, Clone, Copy)]
pub(super) enum Body {
    Torque(RobotParams),
    Velocity(VelocityRobot),
}
