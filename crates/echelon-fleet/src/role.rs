//! The fleet's process roles, named once: what each process is, as its
//! report says it (`"role": "robot"`) and `fleet up` reads it back.

use serde::{Deserialize, Serialize};

/// What a fleet process is.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Role {
    /// Publishes the reference (`fleet leader`).
    Leader,
    /// Drives one agent (`fleet robot`).
    Robot,
    /// Records the fleet (`fleet collector`).
    Collector,
    /// A simulated ROS 2 base (`fleet base`).
    Base,
    /// A Zenoh router (`fleet router`).
    Router,
    /// Drives a base with an excitation signal (`fleet excite`).
    Excite,
}

impl Role {
    /// Its name, as in reports and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Role::Leader => "leader",
            Role::Robot => "robot",
            Role::Collector => "collector",
            Role::Base => "base",
            Role::Router => "router",
            Role::Excite => "excite",
        }
    }
}

impl std::fmt::Display for Role {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use super::*;

    #[test]
    fn names_are_the_serialised_names() {
        for r in [
            Role::Leader,
            Role::Robot,
            Role::Collector,
            Role::Base,
            Role::Router,
            Role::Excite,
        ] {
            assert_eq!(serde_json::to_string(&r).unwrap(), format!("\"{r}\""));
            assert_eq!(
                serde_json::from_str::<Role>(&format!("\"{r}\"")).unwrap(),
                r
            );
        }
    }
}
