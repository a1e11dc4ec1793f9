//! Zenoh's reading of an access-control section (default deny; a message is
//! allowed when a policy of a matching subject has an allowing rule of its
//! flow and kind whose key expressions include its key), shared by the unit
//! tests of `net::acl` and the real-robots guide's test.

use serde_json::Value;
use zenoh::key_expr::keyexpr;

/// The strings of a JSON array (none if it is not one).
pub(crate) fn strs(v: &Value) -> Vec<&str> {
    v.as_array()
        .map(|a| a.iter().filter_map(Value::as_str).collect())
        .unwrap_or_default()
}

/// Whether the key expression `expr` includes the key `key`.
pub(crate) fn includes(expr: &str, key: &str) -> bool {
    match (keyexpr::new(expr), keyexpr::new(key)) {
        (Ok(e), Ok(k)) => e.includes(k),
        _ => panic!("not key expressions: {expr}, {key}"),
    }
}

/// Whether `acl` lets `message` on `key` flow `flow` for a link matching
/// `matches` (a subject), by Zenoh's reading.
pub(crate) fn allows(
    acl: &Value,
    matches: impl Fn(&Value) -> bool,
    flow: &str,
    message: &str,
    key: &str,
) -> bool {
    assert_eq!(acl["default_permission"], "deny");
    let subjects: Vec<&str> = acl["subjects"]
        .as_array()
        .into_iter()
        .flatten()
        .filter(|s| matches(s))
        .filter_map(|s| s["id"].as_str())
        .collect();
    let rules: Vec<&str> = acl["policies"]
        .as_array()
        .into_iter()
        .flatten()
        .filter(|p| strs(&p["subjects"]).iter().any(|s| subjects.contains(s)))
        .flat_map(|p| strs(&p["rules"]))
        .collect();
    acl["rules"].as_array().into_iter().flatten().any(|r| {
        r["permission"] == "allow"
            && rules.contains(&r["id"].as_str().unwrap_or_default())
            && strs(&r["flows"]).contains(&flow)
            && strs(&r["messages"]).contains(&message)
            && strs(&r["key_exprs"]).iter().any(|e| includes(e, key))
    })
}
