//! ROS 2 names (topics, namespaces, nodes) by the rules of ROS 2's
//! `rcl` name validation, and how a topic maps onto Zenoh keys
//! ([`KeyScheme`]). Used by the scenario's `[fleet.ros2]` section (crate `echelon`, to refuse a
//! bad name with its place in the file), by [`crate::keys`] and
//! [`crate::liveliness`].

/// How topics map onto Zenoh keys.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[cfg_attr(feature = "schemars", derive(schemars::JsonSchema))]
#[serde(rename_all = "snake_case")]
pub enum KeyScheme {
    /// rmw_zenoh's `<domain>/<topic>/<type>/<hash>` (Jazzy and later: the
    /// RIHS01 type hash).
    #[default]
    RmwZenoh,
    /// rmw_zenoh on ROS 2 Humble: the same keys and tokens with
    /// `TypeHashNotSupported` where the type hash stands (Humble has no
    /// type hashes; rmw_zenoh's `humble` branch, and ZettaScale's `hiroz`
    /// under its `no-type-hash` feature, write this constant).
    RmwZenohHumble,
    /// zenoh-bridge-ros2dds's plain `<topic>`.
    Bridge,
}

/// A ROS name that is not valid.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("ROS name `{name}`: {reason}")]
pub struct NameError {
    /// The name as given.
    pub name: String,
    /// Why it is refused.
    pub reason: &'static str,
}

fn check_tokens(name: &str, path: &str) -> Result<(), NameError> {
    let refuse = |reason| {
        Err(NameError {
            name: name.to_owned(),
            reason,
        })
    };
    if path.ends_with('/') {
        return refuse("ends with `/`");
    }
    for token in path.split('/') {
        if token.is_empty() {
            return refuse("has an empty segment (`//`)");
        }
        if token.starts_with(|c: char| c.is_ascii_digit()) {
            return refuse("a segment starts with a digit");
        }
        if !token.chars().all(|c| c.is_ascii_alphanumeric() || c == '_') {
            return refuse(
                "only letters, digits, `_` and `/` are allowed (no `~` or `{}` substitutions)",
            );
        }
    }
    Ok(())
}

/// The fully qualified topic name (`/ns/topic`) of `topic` in `namespace`,
/// by the ROS 2 rules: an absolute topic (leading `/`) ignores the
/// namespace; a relative one is appended to it. The namespace may be empty,
/// `/`, `/robot1` or `robot1`. Private names (`~`) and substitutions (`{}`)
/// are refused.
pub fn fully_qualified_topic(namespace: &str, topic: &str) -> Result<String, NameError> {
    if topic.is_empty() {
        return Err(NameError {
            name: topic.to_owned(),
            reason: "is empty",
        });
    }
    if let Some(absolute) = topic.strip_prefix('/') {
        check_tokens(topic, absolute)?;
        return Ok(topic.to_owned());
    }
    check_tokens(topic, topic)?;
    let ns = normalize_namespace(namespace)?;
    Ok(if ns == "/" {
        format!("/{topic}")
    } else {
        format!("{ns}/{topic}")
    })
}

/// A namespace in its canonical form: `/` for the root, else `/a/b` (no
/// trailing slash).
pub fn normalize_namespace(namespace: &str) -> Result<String, NameError> {
    let inner = namespace.trim_start_matches('/');
    if inner.is_empty() {
        return Ok("/".to_owned());
    }
    if namespace.starts_with("//") {
        return Err(NameError {
            name: namespace.to_owned(),
            reason: "has an empty segment (`//`)",
        });
    }
    check_tokens(namespace, inner)?;
    Ok(format!("/{inner}"))
}

/// A node name: one segment of letters, digits and `_`, not starting with a digit.
pub fn check_node_name(name: &str) -> Result<(), NameError> {
    if name.is_empty() || name.contains('/') {
        return Err(NameError {
            name: name.to_owned(),
            reason: "a node name is one non-empty segment",
        });
    }
    check_tokens(name, name)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_qualify_by_the_ros_rules() {
        let fq = |ns, t| fully_qualified_topic(ns, t).map_err(|e| e.reason);
        assert_eq!(fq("", "cmd_vel"), Ok("/cmd_vel".to_owned()));
        assert_eq!(fq("/", "cmd_vel"), Ok("/cmd_vel".to_owned()));
        assert_eq!(fq("/robot1", "cmd_vel"), Ok("/robot1/cmd_vel".to_owned()));
        assert!(fq("robot1/", "cmd_vel").is_err());
        assert_eq!(
            fq("robot1", "diff/cmd_vel"),
            Ok("/robot1/diff/cmd_vel".to_owned())
        );
        assert_eq!(fq("/robot1", "/odom"), Ok("/odom".to_owned()));
        assert!(fq("/robot1", "~/odom").is_err());
        assert!(fq("/robot1", "{node}/odom").is_err());
        assert!(fq("/robot1", "a//b").is_err());
        assert!(fq("/robot1", "odom/").is_err());
        assert!(fq("/robot1", "1odom").is_err());
        assert!(fq("/robot1", "").is_err());
        assert!(fq("/1robot", "odom").is_err());
        assert!(check_node_name("echelon_robot_1").is_ok());
        assert!(check_node_name("a/b").is_err());
    }
}
