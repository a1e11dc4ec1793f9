//! The fleet's process roles, named once: what each process is, as its
//! report says it (`"role": "robot"`) and `fleet up` reads it back.
//!
//! The names of the roles are written here only: liveliness tokens
//! ([`Member::liveliness`]), certificate identities ([`Member::identity`])
//! and the access control ([`crate::net::access_control`]) derive from
//! [`Role`] and [`Member`]. What each role does is a
//! [`crate::runtime::Task`], run by the [one runtime](crate::runtime).

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
    /// Sends the fleet-wide commands (`fleet stop`, `fleet resume`).
    Operator,
}

impl Role {
    /// Every role.
    pub const ALL: [Role; 7] = [
        Role::Leader,
        Role::Robot,
        Role::Collector,
        Role::Base,
        Role::Router,
        Role::Excite,
        Role::Operator,
    ];

    /// Its name, as in reports and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Role::Leader => "leader",
            Role::Robot => "robot",
            Role::Collector => "collector",
            Role::Base => "base",
            Role::Router => "router",
            Role::Excite => "excite",
            Role::Operator => "operator",
        }
    }
}

impl std::fmt::Display for Role {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for Role {
    type Err = String;

    fn from_str(s: &str) -> Result<Role, String> {
        Role::ALL
            .into_iter()
            .find(|r| r.name() == s)
            .ok_or_else(|| format!("no role {s:?}"))
    }
}

/// One process of a fleet: its role and, for the roles of one agent, the
/// agent (from 1).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Member {
    /// The leader.
    Leader,
    /// Robot `k`.
    Robot(u32),
    /// The collector.
    Collector,
    /// Agent `k`'s simulated ROS 2 base.
    Base(u32),
    /// A router (every router has the same identity).
    Router,
    /// `fleet excite` on agent `k`'s robot (in its place, with its identity).
    Excite(u32),
    /// `fleet stop` and `fleet resume`: the one identity besides the leader
    /// that may put the fleet command.
    Operator,
}

impl Member {
    /// Every member of a fleet of `robots` robots (each with a base and
    /// an exciter), and its operator.
    pub fn all(robots: u32) -> Vec<Member> {
        [
            Member::Leader,
            Member::Collector,
            Member::Router,
            Member::Operator,
        ]
        .into_iter()
        .chain((1..=robots).map(Member::Robot))
        .chain((1..=robots).map(Member::Base))
        .chain((1..=robots).map(Member::Excite))
        .collect()
    }

    /// Its role.
    pub fn role(self) -> Role {
        match self {
            Member::Leader => Role::Leader,
            Member::Robot(_) => Role::Robot,
            Member::Collector => Role::Collector,
            Member::Base(_) => Role::Base,
            Member::Router => Role::Router,
            Member::Excite(_) => Role::Excite,
            Member::Operator => Role::Operator,
        }
    }

    /// Its agent, for the roles of one agent.
    pub fn agent(self) -> Option<u32> {
        match self {
            Member::Robot(k) | Member::Base(k) | Member::Excite(k) => Some(k),
            Member::Leader | Member::Collector | Member::Router | Member::Operator => None,
        }
    }

    /// Its name in liveliness tokens, `--wait-for` and `fleet up`'s
    /// messages: `leader`, `collector`, `router`, `operator`, `robot/<k>`,
    /// `base/<k>`, `excite/<k>`.
    pub fn liveliness(self) -> String {
        match self.agent() {
            Some(k) => format!("{}/{k}", self.role()),
            None => self.role().name().to_owned(),
        }
    }

    /// Its identity (certificate and access-control subject): `leader`,
    /// `collector`, `router`, `operator`, `robot-<k>`, `base-<k>`; an exciter drives
    /// its robot in its place, as `robot-<k>`.
    pub fn identity(self) -> String {
        let role = match self {
            Member::Excite(_) => Role::Robot,
            m => m.role(),
        };
        match self.agent() {
            Some(k) => format!("{role}-{k}"),
            None => role.name().to_owned(),
        }
    }
}

impl std::fmt::Display for Member {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.liveliness())
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use super::*;

    #[test]
    fn names_are_the_serialised_names() {
        for r in Role::ALL {
            assert_eq!(r.name().parse::<Role>(), Ok(r));
            assert_eq!(serde_json::to_string(&r).unwrap(), format!("\"{r}\""));
            assert_eq!(
                serde_json::from_str::<Role>(&format!("\"{r}\"")).unwrap(),
                r
            );
        }
    }
}

#[cfg(test)]
mod member_tests {
    use super::*;

    #[test]
    fn members_are_named_as_before() {
        assert_eq!(Member::Robot(3).liveliness(), "robot/3");
        assert_eq!(Member::Base(2).liveliness(), "base/2");
        assert_eq!(Member::Leader.liveliness(), "leader");
        assert_eq!(Member::Robot(3).identity(), "robot-3");
        assert_eq!(Member::Excite(3).identity(), "robot-3");
        assert_eq!(Member::Base(1).identity(), "base-1");
        assert_eq!(Member::Router.identity(), "router");
        assert_eq!(Member::Operator.identity(), "operator");
        assert_eq!(Member::Operator.liveliness(), "operator");
        assert_eq!(Member::all(2).len(), 10);
    }
}
