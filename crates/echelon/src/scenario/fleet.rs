//! The `[fleet]` section resolved: what `echelon fleet` needs beyond the
//! simulation (fleet name, rates, link-loss policies).

use super::locate::FieldPath;
use super::{Merge, Scenario};
use crate::check;
use crate::error::ScenarioError;

/// Default reference publication rate, Hz.
pub const DEFAULT_REFERENCE_RATE: f64 = 50.0;
/// Default robot controller rate, Hz.
pub const DEFAULT_CONTROL_RATE: f64 = 100.0;
/// Default time without a fresh message after which a leader stream is lost, s.
pub const DEFAULT_LINK_TIMEOUT: f64 = 0.2;
/// Default age on arrival beyond which a message is stale, s.
pub const DEFAULT_STALE_AFTER: f64 = 0.5;
/// Default `extrapolate` hold time, s.
pub const DEFAULT_HOLD: f64 = 1.0;
/// Default peak deceleration of `extrapolate`'s stop, m/s².
pub const DEFAULT_DECEL: f64 = 0.1;

/// What a robot does when its leader's stream is lost (`policy = "stop"` or
/// `"extrapolate"` in a scenario).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Deserialize, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum LinkPolicy {
    /// Converge to the last received position (the paper's experiment).
    Stop,
    /// Keep the last `V_d`, `ω_d` for the hold time, then slow smoothly to rest.
    #[default]
    Extrapolate,
}

/// A resolved link-loss policy.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LinkLoss {
    /// Stop or extrapolate.
    pub policy: LinkPolicy,
    /// `extrapolate`: how long the last speed is kept after the last message, s.
    pub hold: f64,
    /// `extrapolate`: peak deceleration of the smooth stop, m/s².
    pub decel: f64,
}

impl Default for LinkLoss {
    fn default() -> Self {
        LinkLoss {
            policy: LinkPolicy::Extrapolate,
            hold: DEFAULT_HOLD,
            decel: DEFAULT_DECEL,
        }
    }
}

/// The `[fleet]` settings with defaults applied and values checked.
#[derive(Debug, Clone, PartialEq)]
pub struct FleetSettings {
    /// Fleet name: the second chunk of every key expression.
    pub name: String,
    /// Reference publication rate, Hz.
    pub reference_rate: f64,
    /// Robot controller rate, Hz.
    pub control_rate: f64,
    /// Link-loss detection time, s.
    pub link_timeout: f64,
    /// Staleness threshold on a message's age at arrival, s.
    pub stale_after: f64,
    /// Per agent (0-based), its link-loss policy.
    pub link_loss: Vec<LinkLoss>,
}

/// Whether `s` can be one chunk of a Zenoh key expression as echelon uses it:
/// non-empty, ASCII letters, digits, `-`, `_` and `.` only.
pub fn is_valid_fleet_name(s: &str) -> bool {
    !s.is_empty()
        && s.bytes()
            .all(|b| b.is_ascii_alphanumeric() || matches!(b, b'-' | b'_' | b'.'))
}

impl Scenario {
    /// Resolves and checks the `[fleet]` section and every agent's `link_loss`.
    pub fn fleet(&self) -> Result<FleetSettings, ScenarioError> {
        let f = &self.file.fleet;
        let at = FieldPath::from("fleet");
        for (i, a) in self.file.agents.iter().enumerate() {
            let name = a.robot.as_deref().unwrap_or("agent1");
            let velocity = match self.file.robots.get(name) {
                Some(r) => match r.drive {
                    Some(d) => d == super::schema::DriveName::Velocity,
                    None => r
                        .preset
                        .as_deref()
                        .is_some_and(|p| crate::base::VelocityRobot::preset(p).is_some()),
                },
                None => crate::base::VelocityRobot::preset(name).is_some(),
            };
            if velocity {
                return Err(self.error(
                    &FieldPath::from("agents").index(i).key("robot"),
                    format!(
                        "`{name}` is a velocity base: fleet robots drive the torque plant (eq. 3) only so far"
                    ),
                ));
            }
        }
        let name = match &f.name {
            Some(n) => {
                if !is_valid_fleet_name(n) {
                    return Err(self.error(
                        &at.key("name"),
                        format!("`{n}` is not a valid fleet name (letters, digits, '-', '_' and '.' only; it becomes a key expression chunk)"),
                    ));
                }
                n.clone()
            }
            None => {
                let cleaned: String = self
                    .name()
                    .chars()
                    .map(|c| {
                        if c.is_ascii_alphanumeric() || matches!(c, '-' | '_' | '.') {
                            c
                        } else {
                            '-'
                        }
                    })
                    .collect();
                if cleaned.is_empty() {
                    "fleet".to_owned()
                } else {
                    cleaned
                }
            }
        };
        let positive = |v: Option<f64>, key: &str, default: f64| -> Result<f64, ScenarioError> {
            check::positive("", v.unwrap_or(default))
                .map_err(|e| self.locator().param(&at.key(key), &e))
        };
        let reference_rate = positive(f.reference_rate, "reference_rate", DEFAULT_REFERENCE_RATE)?;
        let control_rate = positive(f.control_rate, "control_rate", DEFAULT_CONTROL_RATE)?;
        let link_timeout = positive(f.link_timeout, "link_timeout", DEFAULT_LINK_TIMEOUT)?;
        let stale_after = positive(f.stale_after, "stale_after", DEFAULT_STALE_AFTER)?;
        let link_loss = self
            .file
            .agents
            .iter()
            .enumerate()
            .map(|(i, a)| {
                let links = Merge::new(
                    a.link_loss.as_ref(),
                    f.link_loss.as_ref(),
                    FieldPath::from("agents").index(i).key("link_loss"),
                    at.key("link_loss"),
                );
                let pick = |get, key: &str, default: f64| {
                    let (v, path) = links.get_or(get, key, default);
                    check::non_negative("", v).map_err(|e| self.locator().param(&path, &e))
                };
                let hold = pick(|l| l.hold, "hold", DEFAULT_HOLD)?;
                let decel = pick(|l| l.decel, "decel", DEFAULT_DECEL)?;
                if decel == 0.0 {
                    let (_, path) = links.get_or(|l| l.decel, "decel", decel);
                    return Err(self.error(&path, "0 must be > 0 (a robot must be able to stop)"));
                }
                let (policy, _) = links.get_or(|l| l.policy, "policy", LinkPolicy::Extrapolate);
                Ok(LinkLoss {
                    policy,
                    hold,
                    decel,
                })
            })
            .collect::<Result<Vec<_>, ScenarioError>>()?;
        Ok(FleetSettings {
            name,
            reference_rate,
            control_rate,
            link_timeout,
            stale_after,
            link_loss,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scenario::builtin;

    const BASE: &str = r#"
[sim]
duration = 1.0
dt = 0.01

[reference.circle]
speed = 0.1
turn_rate = 0.1
start = { x = 0.0, y = 0.0, theta = 0.0 }

[[agents]]
start = { x = 0.0, y = 0.0, theta = 0.0 }
leader = "reference"
offset = { x = 0.3, y = 0.0 }
"#;

    fn parse(extra: &str) -> Result<FleetSettings, ScenarioError> {
        Scenario::parse(&format!("{BASE}{extra}"), "t.toml", None)?.fleet()
    }

    #[test]
    fn every_builtin_has_the_defaults() {
        for (name, src) in builtin() {
            let s = Scenario::parse(src, name, None).unwrap_or_else(|e| panic!("{e}"));
            if name.ends_with("-velocity") || name.starts_with("turtlebot") {
                // Velocity bases are refused by the fleet so far.
                let e = s.fleet().expect_err("a velocity base in the fleet");
                assert!(e.message.contains("velocity base"), "{e}");
                continue;
            }
            let f = s.fleet().unwrap_or_else(|e| panic!("{e}"));
            assert_eq!(f.name, *name);
            assert_eq!(f.reference_rate, DEFAULT_REFERENCE_RATE);
            assert_eq!(f.control_rate, DEFAULT_CONTROL_RATE);
            assert!(f.link_loss.iter().all(|l| *l == LinkLoss::default()));
        }
    }

    #[test]
    fn agent_settings_override_the_fleet_section() {
        let f = parse(
            "link_loss = { policy = \"stop\" }\n\n[fleet]\nname = \"lab.1\"\ncontrol_rate = 200\nlink_loss = { hold = 2.5 }\n",
        )
        .unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(f.name, "lab.1");
        assert_eq!(f.control_rate, 200.0);
        assert_eq!(
            f.link_loss[0],
            LinkLoss {
                policy: LinkPolicy::Stop,
                hold: 2.5,
                decel: DEFAULT_DECEL
            }
        );
    }

    #[test]
    fn bad_values_are_located() {
        let e = parse("\n[fleet]\nname = \"a/b\"\n")
            .err()
            .unwrap_or_else(|| panic!());
        assert_eq!(e.field, "fleet.name");
        assert!(
            e.location.line > 0 && e.message.contains("fleet name"),
            "{e}"
        );
        let e = parse("link_loss = { decel = -1.0 }\n")
            .err()
            .unwrap_or_else(|| panic!());
        assert_eq!(e.field, "agents[1].link_loss.decel");
        assert!(e.location.line > 0, "{e}");
        // A robot that cannot stop, set by the agent or by the file.
        let e = parse("link_loss = { decel = 0.0 }\n")
            .err()
            .unwrap_or_else(|| panic!());
        assert_eq!(e.field, "agents[1].link_loss.decel");
        assert!(e.message.contains("able to stop"), "{e}");
        let e = parse("\n[fleet.link_loss]\ndecel = 0.0\n")
            .err()
            .unwrap_or_else(|| panic!());
        assert_eq!(e.field, "fleet.link_loss.decel");
        assert!(e.message.contains("able to stop"), "{e}");
        let e = parse("\n[fleet.link_loss]\nhold = -1.0\n")
            .err()
            .unwrap_or_else(|| panic!());
        assert_eq!(e.field, "fleet.link_loss.hold");
        let e = parse("\n[fleet]\ncontrol_rate = 0\n")
            .err()
            .unwrap_or_else(|| panic!());
        assert_eq!(e.field, "fleet.control_rate");
        let e = parse("\n[fleet]\nrate = 5\n")
            .err()
            .unwrap_or_else(|| panic!());
        assert!(e.message.contains("unknown field"), "{e}");
        assert!(!is_valid_fleet_name("") && is_valid_fleet_name("a-b_c.9"));
    }
}
