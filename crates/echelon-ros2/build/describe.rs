//! What ROS 2 derives from a message's `.msg` and those it nests:
//!
//! - the RIHS01 type hash (REP 2011; `rosidl_generator_type_description`):
//!   SHA-256 of the JSON of the type description, the type's fields then
//!   every type it nests (transitively, sorted by name), default values
//!   and constants left out, written as Python's `json.dumps(..., separators=(', ', ': '))`;
//! - the full definition rosbag2 stores as an MCAP `ros2msg` schema
//!   (`LocalMessageDefinitionSource::get_full_text`): the type's `.msg`,
//!   then, depth first and each type once, every nested type's `.msg`
//!   after a line of 80 `=` and a `MSG: <package>/<Type>` line, dependencies
//!   in sorted order of their names.

use std::collections::{BTreeMap, BTreeSet};
use std::fmt::Write as _;

use crate::msg::{Base, Msg, full_name};

/// `type_description_interfaces/msg/FieldType`: a nested message.
const FIELD_TYPE_NESTED_TYPE: u8 = 1;
/// Added to a scalar's id for a fixed-size array of it.
const FIELD_TYPE_ARRAY_OFFSET: u8 = 48;
/// Added to a scalar's id for an unbounded sequence of it.
const FIELD_TYPE_UNBOUNDED_SEQUENCE_OFFSET: u8 = 144;

/// `RIHS01_` and the 64 hex digits of the type hash of `msg`.
pub(crate) fn type_hash(msg: &Msg, all: &BTreeMap<String, Msg>) -> String {
    let mut referenced = BTreeSet::new();
    collect_nested(msg, all, &mut referenced);
    let referenced: Vec<String> = referenced
        .iter()
        .map(|short| describe(&all[short]))
        .collect();
    let json = format!(
        "{{\"type_description\": {}, \"referenced_type_descriptions\": [{}]}}",
        describe(msg),
        referenced.join(", ")
    );
    let digest = sha2_const_stable::Sha256::new()
        .update(json.as_bytes())
        .finalize();
    let mut hex = String::from("RIHS01_");
    for b in digest {
        let _ = write!(hex, "{b:02x}");
    }
    hex
}

/// Every message `msg` nests, at any depth, by `package/Type`.
fn collect_nested(msg: &Msg, all: &BTreeMap<String, Msg>, out: &mut BTreeSet<String>) {
    for dep in msg.dependencies() {
        if out.insert(dep.clone()) {
            collect_nested(&all[&dep], all, out);
        }
    }
}

/// `{"type_name": ..., "fields": [...]}` without default values.
fn describe(msg: &Msg) -> String {
    let fields: Vec<String> = msg
        .fields
        .iter()
        .map(|f| {
            let (scalar, nested) = match &f.base {
                Base::Primitive(p) => (p.type_id(), String::new()),
                Base::Nested(n) => (FIELD_TYPE_NESTED_TYPE, full_name(n)),
            };
            let (type_id, capacity) = match (f.array, f.sequence) {
                (Some(n), _) => (scalar + FIELD_TYPE_ARRAY_OFFSET, n),
                (None, true) => (scalar + FIELD_TYPE_UNBOUNDED_SEQUENCE_OFFSET, 0),
                (None, false) => (scalar, 0),
            };
            format!(
                "{{\"name\": \"{}\", \"type\": {{\"type_id\": {type_id}, \"capacity\": {capacity}, \
                 \"string_capacity\": 0, \"nested_type_name\": \"{nested}\"}}}}",
                f.name
            )
        })
        .collect();
    format!(
        "{{\"type_name\": \"{}\", \"fields\": [{}]}}",
        msg.full_name(),
        fields.join(", ")
    )
}

/// The full definition of `msg`, as rosbag2 writes it.
pub(crate) fn full_definition(msg: &Msg, all: &BTreeMap<String, Msg>) -> String {
    let mut seen = BTreeSet::new();
    let mut out = String::new();
    append_definition(msg, all, &mut seen, &mut out);
    out
}

fn append_definition(
    msg: &Msg,
    all: &BTreeMap<String, Msg>,
    seen: &mut BTreeSet<String>,
    out: &mut String,
) {
    out.push_str(&msg.text);
    for dep in msg.dependencies() {
        if seen.insert(dep.clone()) {
            let _ = write!(out, "\n{}\nMSG: {dep}\n", "=".repeat(80));
            append_definition(&all[&dep], all, seen, out);
        }
    }
}
