//! The JSON schemas of the collector's own MCAP channels (`/rejected`,
//! `/agent/K/stats`, `/fleet/command`).

use std::borrow::Cow;

use echelon_mcap::JsonSchema;

/// A draft-07 object schema titled `$name`: its description, its
/// properties (the lines inside `"properties"`) and its required list.
macro_rules! object_schema {
    ($name:literal, $description:literal, $properties:literal, $required:literal $(,)?) => {
        JsonSchema {
            name: $name,
            schema: Cow::Borrowed(concat!(
                "{\n  \"$schema\": \"http://json-schema.org/draft-07/schema#\",\n  \"title\": \"",
                $name,
                "\",\n  \"description\": \"",
                $description,
                "\",\n  \"type\": \"object\",\n  \"properties\": {\n",
                $properties,
                "\n  },\n  \"required\": ",
                $required,
                "\n}"
            )),
        }
    };
}

/// Schema of `/rejected`.
pub const REJECTED: JsonSchema = object_schema!(
    "echelon.Rejected",
    "A sample received under the fleet's keys that was not a valid message for its key.",
    r#"    "key": {"type": "string"},
    "reason": {"type": "string"},
    "size": {"type": "integer"},
    "hex": {"type": "string", "description": "the payload, hexadecimal (first 1024 bytes)"}"#,
    r#"["key", "reason", "size", "hex"]"#,
);

/// Schema of `/agent/K/stats` (a robot's counters, as it published them).
pub const STATS: JsonSchema = object_schema!(
    "echelon.RobotStats",
    "A robot's receive counters and link status (docs/fleet.md).",
    r#"    "agent": {"type": "integer"},
    "t": {"type": "number"},
    "link": {"type": "string"},
    "counters": {"type": "object"},
    "published": {"type": "integer"},
    "overruns": {"type": "integer"},
    "safety": {"type": "object", "description": "with [safety]: the filter's counters so far (steps, active, infeasible, stale_brakes, deadlock_breaks, stale_neighbours, lagging, refused, min_distance)"},
    "commands": {"type": "object", "description": "what the fleet commands did so far (received, stops, resumes, refused, ignored)"}"#,
    r#"["agent", "t", "link", "counters"]"#,
);

/// Schema of `/fleet/command` (the fleet commands, as their sender put them).
pub const COMMAND: JsonSchema = object_schema!(
    "echelon.FleetCommand",
    "A fleet-wide stop or resume (fleet stop, fleet resume, the leader interrupted; docs/fleet.md).",
    r#"    "version": {"type": "integer"},
    "order": {"type": "string", "enum": ["stop", "resume"]},
    "seq": {"type": "integer", "description": "a resume lifts only the stops numbered below it"},
    "stamp_unix_ns": {"type": "integer"},
    "by": {"type": "string"},
    "reason": {"type": "string"}"#,
    r#"["version", "order", "seq", "stamp_unix_ns", "by", "reason"]"#,
);

#[cfg(test)]
mod tests {
    /// Each schema is a JSON object schema titled with its name, whose
    /// required fields are among its properties.
    #[test]
    fn each_schema_is_json_titled_with_its_name() {
        for s in [super::REJECTED, super::STATS, super::COMMAND] {
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
        }
    }
}
