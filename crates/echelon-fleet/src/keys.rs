//! Key expressions, all under `echelon/<fleet>/`:
//!
//! | key | publisher | payload |
//! |---|---|---|
//! | `echelon/<fleet>/reference` | leader | reference sample ([`crate::wire`], binary) |
//! | `echelon/<fleet>/robot/<k>/state` | robot `k` (from 1) | robot state ([`crate::wire`], binary); read by the collector, robot `k`'s followers and, with `[safety]`, every other robot |
//! | `echelon/<fleet>/robot/<k>/stats` | robot `k` | its counters, JSON, once per fleet second and at exit |
//! | `echelon/<fleet>/alive/<role>` | every process | liveliness token ([`crate::role::Member::liveliness`]: `leader`, `collector`, `robot/<k>`, `base/<k>`) |
//! | `echelon/<fleet>/operator/heartbeat` | `fleet heartbeat` (the `operator`), with `[fleet] operator_heartbeat` | operator heartbeat ([`crate::heartbeat`], 12 bytes) |
//! | `echelon/<fleet>/command` | `fleet stop` / `fleet resume` (the `operator`), the leader when interrupted | fleet command ([`crate::command::FleetCommand`], JSON) |
//! | `echelon/<fleet>/latch/<role>` | every robot and the leader, as a queryable | the command in force ([`crate::command::Latched`], JSON), answered to queries on `latch/**` |
//! | `echelon/<fleet>/probe/<role>` | every robot and every router (for every fleet: `echelon/*/probe/router`), as a queryable | who answers and its wall clock ([`crate::probe::ProbeAnswer`], JSON): `fleet doctor`'s clock offsets and round trips |
//!
//! The collector subscribes to `echelon/<fleet>/**`.

/// First chunk of every key.
pub const ROOT: &str = "echelon";

/// `echelon/**`: every key of every fleet.
pub fn every_fleet() -> String {
    format!("{ROOT}/**")
}

/// The fleet chunk standing for every fleet ([`Keys::any`]).
const ANY_FLEET: &str = "*";

// The chunks after `echelon/<fleet>/`, each written once.
const REFERENCE: &str = "reference";
const ROBOT: &str = "robot";
const STATE: &str = "state";
const STATS: &str = "stats";
const ALIVE: &str = "alive";
const COMMAND: &str = "command";
const LATCH: &str = "latch";
const HALT: &str = "halt";
const OPERATOR: &str = "operator";
const HEARTBEAT: &str = "heartbeat";
const PROBE: &str = "probe";

/// The key expressions of one fleet.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Keys {
    fleet: String,
}

/// What a key of the fleet is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum KeyKind {
    /// The reference stream.
    Reference,
    /// Robot `k`'s state stream.
    State(u32),
    /// Robot `k`'s counters.
    Stats(u32),
    /// The fleet command.
    Command,
    /// Robot `k`'s own fleet stop (its base reported a hazard).
    Halt(u32),
    /// Anything else under the fleet's root.
    Other,
}

impl Keys {
    /// Keys of fleet `fleet` (a valid name, see `echelon::scenario::is_valid_fleet_name`).
    pub fn new(fleet: &str) -> Keys {
        Keys {
            fleet: fleet.to_owned(),
        }
    }

    /// The key expressions of every fleet at once (`echelon/*/…`), for the
    /// access control.
    pub fn any() -> Keys {
        Keys::new(ANY_FLEET)
    }

    /// The fleet name.
    pub fn fleet(&self) -> &str {
        &self.fleet
    }

    /// `echelon/<fleet>/reference`.
    pub fn reference(&self) -> String {
        format!("{ROOT}/{}/{REFERENCE}", self.fleet)
    }

    /// `echelon/<fleet>/robot/<k>/state`.
    pub fn state(&self, k: u32) -> String {
        format!("{ROOT}/{}/{ROBOT}/{k}/{STATE}", self.fleet)
    }

    /// `echelon/<fleet>/robot/*/state`: every robot's state (neighbours for
    /// the safety filter).
    pub fn states(&self) -> String {
        format!("{ROOT}/{}/{ROBOT}/*/{STATE}", self.fleet)
    }

    /// `echelon/<fleet>/robot/<k>/stats`.
    pub fn stats(&self, k: u32) -> String {
        format!("{ROOT}/{}/{ROBOT}/{k}/{STATS}", self.fleet)
    }

    /// `echelon/<fleet>/robot/<k>/halt`: robot `k`'s own fleet stop (its
    /// base reported a hazard), stop-only: every robot and the leader obey
    /// a stop put there by robot `k`, and nothing else ([`crate::command`]).
    pub fn halt(&self, k: u32) -> String {
        format!("{ROOT}/{}/{ROBOT}/{k}/{HALT}", self.fleet)
    }

    /// `echelon/<fleet>/robot/*/halt`: every robot's own stops.
    pub fn halts(&self) -> String {
        format!("{ROOT}/{}/{ROBOT}/*/{HALT}", self.fleet)
    }

    /// `echelon/<fleet>/operator/heartbeat`: the operator heartbeat
    /// ([`crate::heartbeat`]), when the scenario asks for one.
    pub fn heartbeat(&self) -> String {
        format!("{ROOT}/{}/{OPERATOR}/{HEARTBEAT}", self.fleet)
    }

    /// `echelon/<fleet>/alive/<role>`.
    pub fn alive(&self, role: &str) -> String {
        format!("{ROOT}/{}/{ALIVE}/{role}", self.fleet)
    }

    /// `echelon/<fleet>/command`: the fleet-wide stop and resume.
    pub fn command(&self) -> String {
        format!("{ROOT}/{}/{COMMAND}", self.fleet)
    }

    /// `echelon/<fleet>/latch/<role>`: where `role` (a liveliness name)
    /// answers with the command in force.
    pub fn latch(&self, role: &str) -> String {
        format!("{ROOT}/{}/{LATCH}/{role}", self.fleet)
    }

    /// `echelon/<fleet>/probe/<name>`: where the process of liveliness
    /// name `name` (`robot/3`, `router`) answers `fleet doctor`'s probe
    /// ([`crate::probe`]).
    pub fn probe(&self, name: &str) -> String {
        format!("{ROOT}/{}/{PROBE}/{name}", self.fleet)
    }

    /// `echelon/<fleet>/latch/**`: every latch, to query.
    pub fn latches(&self) -> String {
        self.latch("**")
    }

    /// The liveliness name of a latch key of this fleet (`None`: not one).
    pub fn latch_holder<'a>(&self, key: &'a str) -> Option<&'a str> {
        key.strip_prefix(ROOT)?
            .strip_prefix('/')?
            .strip_prefix(self.fleet.as_str())?
            .strip_prefix('/')?
            .strip_prefix(LATCH)?
            .strip_prefix('/')
    }

    /// `echelon/<fleet>/**`.
    pub fn everything(&self) -> String {
        format!("{ROOT}/{}/**", self.fleet)
    }

    /// Classifies a key of this fleet.
    pub fn classify(&self, key: &str) -> KeyKind {
        let Some(rest) = key
            .strip_prefix(ROOT)
            .and_then(|r| r.strip_prefix('/'))
            .and_then(|r| r.strip_prefix(self.fleet.as_str()))
            .and_then(|r| r.strip_prefix('/'))
        else {
            return KeyKind::Other;
        };
        if rest == REFERENCE {
            return KeyKind::Reference;
        }
        if rest == COMMAND {
            return KeyKind::Command;
        }
        let parts: Vec<&str> = rest.split('/').collect();
        if let [ROBOT, num, what] = parts[..]
            && let Ok(k) = num.parse::<u32>()
            && k >= 1
            && k.to_string() == num
        {
            return match what {
                STATE => KeyKind::State(k),
                STATS => KeyKind::Stats(k),
                HALT => KeyKind::Halt(k),
                _ => KeyKind::Other,
            };
        }
        KeyKind::Other
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keys_round_trip_through_classify() {
        let k = Keys::new("lab-1");
        assert_eq!(k.classify(&k.reference()), KeyKind::Reference);
        assert_eq!(k.classify(&k.state(3)), KeyKind::State(3));
        assert_eq!(k.classify(&k.stats(12)), KeyKind::Stats(12));
        assert_eq!(k.classify("echelon/lab-1/robot/0/state"), KeyKind::Other);
        assert_eq!(k.classify("echelon/lab-1/robot/01/state"), KeyKind::Other);
        assert_eq!(k.classify("echelon/other/reference"), KeyKind::Other);
        assert_eq!(k.classify("echelon/lab-1/alive/leader"), KeyKind::Other);
        assert_eq!(k.reference(), "echelon/lab-1/reference");
        assert_eq!(k.classify(&k.command()), KeyKind::Command);
        assert_eq!(k.classify(&k.halt(4)), KeyKind::Halt(4));
        assert_eq!(k.halts(), "echelon/lab-1/robot/*/halt");
        assert_eq!(k.command(), "echelon/lab-1/command");
        assert_eq!(k.latch_holder(&k.latch("robot/2")), Some("robot/2"));
        assert_eq!(k.latch_holder("echelon/lab-2/latch/robot/2"), None);
        assert_eq!(k.classify(&k.latch("leader")), KeyKind::Other);
        assert_eq!(k.probe("robot/2"), "echelon/lab-1/probe/robot/2");
        assert_eq!(k.classify(&k.probe("router")), KeyKind::Other);
        assert_eq!(Keys::any().probe("router"), "echelon/*/probe/router");
    }
}
