//! Every field the scenario parser accepts, and every value of its
//! enumerations, is named in `docs/scenario-format.md`.
//!
//! The accepted names come from the code, not from a list kept by hand: the
//! JSON Schema that `schemars` derives from the parser's own types
//! (`echelon::scenario::schema`, through the same serde attributes the parser
//! uses: renames, `deny_unknown_fields`, externally tagged enums). A field
//! added to the schema, or a value added to one of its enums, fails this test
//! until the doc names it.
//!
//! "Named" means: the name is a whole token of an inline code span (text
//! between backticks outside fenced blocks), e.g. `` `odom_rate` ``,
//! `` `[fleet.ros2]` `` or `` `{ x, y, theta_deg }` ``. A name shown only in
//! a TOML example or in plain prose does not count.
#![allow(clippy::unwrap_used)] // tests fail loudly by design

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

use echelon::scenario::schema::ScenarioFile;
use serde_json::Value;

/// What the parser accepts: every field name and every enumerated string
/// value, each with the places (`agents[].ros2.key_scheme`) it is accepted at.
#[derive(Debug, Default)]
struct Accepted {
    fields: BTreeMap<String, BTreeSet<String>>,
    values: BTreeMap<String, BTreeSet<String>>,
}

impl Accepted {
    /// Everything, name → places.
    fn names(&self) -> BTreeMap<&str, Vec<String>> {
        let mut out: BTreeMap<&str, Vec<String>> = BTreeMap::new();
        for (name, places) in self.fields.iter().chain(&self.values) {
            out.entry(name).or_default().extend(places.iter().cloned());
        }
        out
    }
}

/// The scenario file's JSON Schema, as the parser's types derive it.
fn schema() -> Value {
    serde_json::to_value(schemars::schema_for!(ScenarioFile)).unwrap()
}

/// Walks `node` (at `path`), following `$ref`s into `defs`, collecting the
/// property names and enumerated values it accepts.
fn walk(node: &Value, path: &str, defs: &Value, seen: &mut Vec<String>, out: &mut Accepted) {
    let Some(obj) = node.as_object() else {
        return;
    };
    if let Some(r) = obj.get("$ref").and_then(Value::as_str) {
        let name = r.rsplit('/').next().unwrap_or(r).to_owned();
        // A type already being walked on this path (recursion) adds nothing.
        if !seen.contains(&name) {
            seen.push(name.clone());
            walk(&defs[name.as_str()], path, defs, seen, out);
            seen.pop();
        }
    }
    if let Some(props) = obj.get("properties").and_then(Value::as_object) {
        for (key, sub) in props {
            let at = if path.is_empty() {
                key.clone()
            } else {
                format!("{path}.{key}")
            };
            out.fields
                .entry(key.clone())
                .or_default()
                .insert(at.clone());
            walk(sub, &at, defs, seen, out);
        }
    }
    let mut value = |v: &Value| {
        if let Some(s) = v.as_str() {
            out.values
                .entry(s.to_owned())
                .or_default()
                .insert(format!("{path} = \"{s}\""));
        }
    };
    if let Some(c) = obj.get("const") {
        value(c);
    }
    for v in obj
        .get("enum")
        .and_then(Value::as_array)
        .into_iter()
        .flatten()
    {
        value(v);
    }
    if let Some(items) = obj.get("items") {
        walk(items, &format!("{path}[]"), defs, seen, out);
    }
    if let Some(extra) = obj.get("additionalProperties") {
        walk(extra, &format!("{path}.*"), defs, seen, out);
    }
    for key in ["oneOf", "anyOf", "allOf", "prefixItems"] {
        for sub in obj.get(key).and_then(Value::as_array).into_iter().flatten() {
            walk(sub, path, defs, seen, out);
        }
    }
}

/// What the scenario parser accepts, from the derived schema.
fn accepted() -> Accepted {
    let schema = schema();
    let defs = schema.get("$defs").cloned().unwrap_or(Value::Null);
    let mut out = Accepted::default();
    walk(&schema, "", &defs, &mut Vec::new(), &mut out);
    out
}

/// Whether `c` can be part of a name token (`theta_deg`, `per-axis`).
fn is_token_char(c: char) -> bool {
    c.is_ascii_alphanumeric() || c == '_' || c == '-'
}

/// Applies `f` to each inline code span of `doc` (outside fenced blocks),
/// rebuilding the text with what `f` returns for the span.
fn map_code_spans(doc: &str, mut f: impl FnMut(&str) -> String) -> String {
    let mut out = String::with_capacity(doc.len());
    let mut fenced = false;
    for line in doc.split_inclusive('\n') {
        if line.trim_start().starts_with("```") {
            fenced = !fenced;
            out.push_str(line);
            continue;
        }
        if fenced {
            out.push_str(line);
            continue;
        }
        for (i, part) in line.split('`').enumerate() {
            if i > 0 {
                out.push('`');
            }
            if i % 2 == 1 {
                out.push_str(&f(part));
            } else {
                out.push_str(part);
            }
        }
    }
    out
}

/// Every name token of the doc's inline code spans.
fn documented(doc: &str) -> BTreeSet<String> {
    let mut names = BTreeSet::new();
    map_code_spans(doc, |span| {
        names.extend(
            span.split(|c: char| !is_token_char(c))
                .filter(|t| !t.is_empty())
                .map(str::to_owned),
        );
        span.to_owned()
    });
    names
}

/// The accepted names `doc` does not name, with where they are accepted.
fn missing(accepted: &Accepted, doc: &str) -> BTreeMap<String, Vec<String>> {
    let named = documented(doc);
    accepted
        .names()
        .into_iter()
        .filter(|(name, _)| !named.contains(*name))
        .map(|(name, places)| (name.to_owned(), places))
        .collect()
}

/// `doc` with every code-span token equal to `name` replaced: the doc as if
/// the field (or value) had been deleted from it.
fn without(doc: &str, name: &str) -> String {
    map_code_spans(doc, |span| {
        let mut out = String::with_capacity(span.len());
        let mut token = String::new();
        let flush = |token: &mut String, out: &mut String| {
            if token == name {
                out.push_str("REMOVED");
            } else {
                out.push_str(token);
            }
            token.clear();
        };
        for c in span.chars() {
            if is_token_char(c) {
                token.push(c);
            } else {
                flush(&mut token, &mut out);
                out.push(c);
            }
        }
        flush(&mut token, &mut out);
        out
    })
}

fn scenario_format_md() -> String {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../docs/scenario-format.md");
    std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// The schema is what the parser reads: it has the sections, nested tables,
/// the reference kinds (an externally tagged enum) and the enumerated values
/// one expects, so the walk below cannot pass by seeing nothing.
#[test]
fn the_derived_schema_has_the_parsers_fields_and_values() {
    let a = accepted();
    for field in [
        "sim",
        "controller_period",
        "bounds",
        "turn_rate",
        "robots",
        "preset",
        "circle",
        "waypoints",
        "t_switch",
        "agents",
        "leader",
        "theta_deg",
        "odom_origin",
        "ros2",
        "key_scheme",
        "cmd_vel_stamp",
        "link_loss",
        "obstacles",
        "fusion",
    ] {
        assert!(a.fields.contains_key(field), "{field} not in the schema");
    }
    for value in [
        "kinematic",
        "per-axis",
        "worst-case",
        "ekf",
        "extrapolate",
        "twist-stamped",
        "zero",
        "now",
        "rmw_zenoh_humble",
        "bridge",
        "tracking",
        "velocity",
    ] {
        assert!(a.values.contains_key(value), "{value} not in the schema");
    }
    assert!(a.fields["key_scheme"].contains("fleet.ros2.key_scheme"));
    assert!(a.fields["key_scheme"].contains("agents[].ros2.key_scheme"));
    assert!(a.fields["speed"].contains("reference.circle.speed"));
    assert!(a.fields["mass"].contains("robots.*.mass"));
    // A name the parser refuses is not in it.
    assert!(!a.fields.contains_key("torque"));
    assert!(!a.fields.contains_key("cmd_vel_rate"));
}

#[test]
fn every_accepted_field_and_value_is_in_scenario_format_md() {
    let missing = missing(&accepted(), &scenario_format_md());
    assert!(
        missing.is_empty(),
        "docs/scenario-format.md does not name (in backticks) these fields or values the parser accepts:\n{}",
        missing
            .iter()
            .map(|(name, places)| format!("  `{name}`: {}", places.join(", ")))
            .collect::<Vec<_>>()
            .join("\n")
    );
}

/// The check fails when a field leaves the doc: for every accepted name, the
/// doc with that name deleted from its code spans is reported missing that
/// name, and only that name.
#[test]
fn removing_any_one_name_from_the_doc_is_reported() {
    let a = accepted();
    let doc = scenario_format_md();
    assert!(missing(&a, &doc).is_empty(), "the doc itself is complete");
    let names = a.names();
    assert!(names.len() > 100, "{} names", names.len());
    for name in names.keys() {
        let cut = without(&doc, name);
        assert_ne!(cut, doc, "`{name}` is in the doc");
        let reported: Vec<String> = missing(&a, &cut).into_keys().collect();
        assert_eq!(reported, vec![(*name).to_owned()], "doc without `{name}`");
    }
}

/// The matching itself: a code-span token counts, prose and fenced blocks do
/// not, and a longer name does not stand for a shorter one.
#[test]
fn only_whole_tokens_of_inline_code_count() {
    let doc = "odom_rate in prose\n\n```toml\nodom_timeout = 1\n```\n\n| `cmd_vel_timeout` | `{ x, theta_deg }` | `\"per-axis\"` |\n";
    let named = documented(doc);
    for t in ["cmd_vel_timeout", "x", "theta_deg", "per-axis"] {
        assert!(named.contains(t), "{t}");
    }
    for t in ["odom_rate", "odom_timeout", "theta", "cmd_vel", "per"] {
        assert!(!named.contains(t), "{t}");
    }
    assert_eq!(
        without(doc, "x"),
        doc.replace("`{ x, theta_deg }`", "`{ REMOVED, theta_deg }`")
    );
}

/// README's table of built-ins lists every built-in scenario
/// (`scenarios/*.toml`), once, and nothing else.
#[test]
fn the_readme_lists_every_built_in() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../README.md");
    let readme = std::fs::read_to_string(&path).unwrap();
    let start = readme
        .find("| built-in | paper | what it shows |")
        .expect("README's table of built-ins");
    let mut listed: Vec<&str> = readme[start..]
        .lines()
        .skip(2)
        .take_while(|l| l.starts_with('|'))
        .filter_map(|l| l.split('`').nth(1))
        .collect();
    listed.sort_unstable();
    let mut builtins: Vec<&str> = echelon::scenario::builtin()
        .iter()
        .map(|(n, _)| *n)
        .collect();
    builtins.sort_unstable();
    assert_eq!(listed, builtins);
}
