//! The JSON schemas of the collector's own MCAP channels (`/rejected`,
//! `/agent/K/stats`, `/fleet/command`), each derived from the type whose
//! JSON the channel carries, so a field added to the type is in its schema.

use std::sync::LazyLock;

use echelon_mcap::JsonSchema;
use serde::Serialize;

use crate::command::FleetCommand;
use crate::robot::RobotStats;

/// A sample received under the fleet's keys that was not a valid message
/// for its key (a `/rejected` message).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, schemars::JsonSchema)]
#[schemars(title = "echelon.Rejected")]
pub(super) struct Rejected<'a> {
    /// The key it arrived on.
    pub key: &'a str,
    /// Why it was refused.
    pub reason: &'a str,
    /// Its payload's size, bytes.
    pub size: usize,
    /// The payload, hexadecimal (first 1024 bytes).
    pub hex: String,
}

/// Schema of `/rejected`, derived from its records.
pub static REJECTED: LazyLock<JsonSchema> =
    LazyLock::new(|| JsonSchema::of::<Rejected<'static>>("echelon.Rejected"));

/// Schema of `/agent/K/stats` (a robot's counters, as it published them),
/// derived from [`RobotStats`].
pub static STATS: LazyLock<JsonSchema> =
    LazyLock::new(|| JsonSchema::of::<RobotStats>("echelon.RobotStats"));

/// Schema of `/fleet/command` (the fleet commands, as their sender put
/// them), derived from [`FleetCommand`].
pub static COMMAND: LazyLock<JsonSchema> =
    LazyLock::new(|| JsonSchema::of::<FleetCommand>("echelon.FleetCommand"));

#[cfg(test)]
mod tests {
    use std::collections::BTreeSet;

    use super::*;
    use crate::command::Order;
    use crate::robot::SafetyCounts;
    use crate::ros2::fixes::FixReport;

    /// Each schema is a JSON object schema titled with its name, whose
    /// required fields are among its properties, and whose properties are
    /// exactly the fields its type writes (every optional one present).
    #[test]
    fn each_schema_is_its_types_json() {
        let stats = RobotStats {
            agent: 2,
            t: 1.5,
            link: "fresh",
            counters: Default::default(),
            published: 3,
            overruns: 0,
            safety: Some(SafetyCounts::default()),
            fixes: Some(FixReport::default()),
            hazards: Some(crate::ros2::hazard::HazardStats {
                in_force: crate::ros2::hazard::HazardSet::EMPTY
                    .with(crate::ros2::hazard::Hazard::Bump),
                counts: Default::default(),
                last: Some(crate::ros2::hazard::HazardEvent {
                    hazard: crate::ros2::hazard::Hazard::Bump,
                    at: 1.0,
                    cleared: None,
                }),
            }),
            commands: Default::default(),
            watchdogs: Default::default(),
            cpu: Some(crate::cost::CpuUse {
                seconds: 1.0,
                share: Some(0.5),
            }),
        };
        let rejected = Rejected {
            key: "echelon/f/x",
            reason: "malformed",
            size: 1,
            hex: "00".to_owned(),
        };
        // Signed: its proof written too.
        let command = FleetCommand::new(Order::Resume, 1, "operator", "test")
            .signed(&crate::testing::operator_token());
        for (s, json) in [
            (&*REJECTED, serde_json::to_value(&rejected)),
            (&*STATS, serde_json::to_value(stats)),
            (&*COMMAND, serde_json::to_value(&command)),
        ] {
            let v: serde_json::Value =
                serde_json::from_str(&s.schema).unwrap_or_else(|e| panic!("{}: {e}", s.name));
            assert_eq!(v["title"], s.name);
            assert_eq!(v["type"], "object");
            let required = v["required"].as_array().map_or(0, Vec::len);
            assert!(required > 0, "{}", s.name);
            for r in v["required"].as_array().into_iter().flatten() {
                let r = r.as_str().unwrap_or_default();
                assert!(v["properties"].get(r).is_some(), "{}: {r}", s.name);
            }
            let json = json.unwrap_or_else(|e| panic!("{}: {e}", s.name));
            let written: BTreeSet<&String> = json
                .as_object()
                .into_iter()
                .flatten()
                .map(|(k, _)| k)
                .collect();
            let declared: BTreeSet<&String> = v["properties"]
                .as_object()
                .into_iter()
                .flatten()
                .map(|(k, _)| k)
                .collect();
            assert_eq!(written, declared, "{}", s.name);
        }
    }
}
