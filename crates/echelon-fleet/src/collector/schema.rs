//! The JSON schemas of the collector's own MCAP channels (`/rejected`,
//! `/agent/K/stats`, `/fleet/command`).

use std::borrow::Cow;

use echelon_mcap::JsonSchema;

/// Schema of `/rejected`.
pub const REJECTED: JsonSchema = JsonSchema {
    name: "echelon.Rejected",
    schema: Cow::Borrowed(
        r#"{
  "$schema": "http://json-schema.org/draft-07/schema#",
  "title": "echelon.Rejected",
  "description": "A sample received under the fleet's keys that was not a valid message for its key.",
  "type": "object",
  "properties": {
    "key": {"type": "string"},
    "reason": {"type": "string"},
    "size": {"type": "integer"},
    "hex": {"type": "string", "description": "the payload, hexadecimal (first 1024 bytes)"}
  },
  "required": ["key", "reason", "size", "hex"]
}"#,
    ),
};

/// Schema of `/agent/K/stats` (a robot's counters, as it published them).
pub const STATS: JsonSchema = JsonSchema {
    name: "echelon.RobotStats",
    schema: Cow::Borrowed(
        r#"{
  "$schema": "http://json-schema.org/draft-07/schema#",
  "title": "echelon.RobotStats",
  "description": "A robot's receive counters and link status (docs/fleet.md).",
  "type": "object",
  "properties": {
    "agent": {"type": "integer"},
    "t": {"type": "number"},
    "link": {"type": "string"},
    "counters": {"type": "object"},
    "published": {"type": "integer"},
    "overruns": {"type": "integer"},
    "safety": {"type": "object", "description": "with [safety]: the filter's counters so far (steps, active, infeasible, stale_brakes, deadlock_breaks, stale_neighbours, lagging, refused, min_distance)"},
    "commands": {"type": "object", "description": "what the fleet commands did so far (received, stops, resumes, refused, ignored)"}
  },
  "required": ["agent", "t", "link", "counters"]
}"#,
    ),
};

/// Schema of `/fleet/command` (the fleet commands, as their sender put them).
pub const COMMAND: JsonSchema = JsonSchema {
    name: "echelon.FleetCommand",
    schema: Cow::Borrowed(
        r#"{
  "$schema": "http://json-schema.org/draft-07/schema#",
  "title": "echelon.FleetCommand",
  "description": "A fleet-wide stop or resume (fleet stop, fleet resume, the leader interrupted; docs/fleet.md).",
  "type": "object",
  "properties": {
    "version": {"type": "integer"},
    "order": {"type": "string", "enum": ["stop", "resume"]},
    "seq": {"type": "integer", "description": "a resume lifts only the stops numbered below it"},
    "stamp_unix_ns": {"type": "integer"},
    "by": {"type": "string"},
    "reason": {"type": "string"}
  },
  "required": ["version", "order", "seq", "stamp_unix_ns", "by", "reason"]
}"#,
    ),
};
