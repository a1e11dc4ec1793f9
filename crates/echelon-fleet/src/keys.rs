//! Key expressions, all under `echelon/<fleet>/`:
//!
//! | key | publisher | payload |
//! |---|---|---|
//! | `echelon/<fleet>/reference` | leader | reference sample ([`crate::wire`], binary) |
//! | `echelon/<fleet>/robot/<k>/state` | robot `k` (from 1) | robot state ([`crate::wire`], binary); read by the collector, robot `k`'s followers and, with `[safety]`, every other robot |
//! | `echelon/<fleet>/robot/<k>/stats` | robot `k` | its counters, JSON, once per fleet second and at exit |
//! | `echelon/<fleet>/alive/<role>` | every process | liveliness token (`leader`, `collector`, `robot/<k>`) |
//!
//! The collector subscribes to `echelon/<fleet>/**`.

/// Robot `k`'s role in liveliness tokens and `--wait-for`: `robot/<k>`.
pub fn robot_role(k: impl std::fmt::Display) -> String {
    format!("robot/{k}")
}

/// First chunk of every key.
pub const ROOT: &str = "echelon";

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

    /// The fleet name.
    pub fn fleet(&self) -> &str {
        &self.fleet
    }

    /// `echelon/<fleet>/reference`.
    pub fn reference(&self) -> String {
        format!("{ROOT}/{}/reference", self.fleet)
    }

    /// `echelon/<fleet>/robot/<k>/state`.
    pub fn state(&self, k: u32) -> String {
        format!("{ROOT}/{}/robot/{k}/state", self.fleet)
    }

    /// `echelon/<fleet>/robot/*/state`: every robot's state (neighbours for
    /// the safety filter).
    pub fn states(&self) -> String {
        format!("{ROOT}/{}/robot/*/state", self.fleet)
    }

    /// `echelon/<fleet>/robot/<k>/stats`.
    pub fn stats(&self, k: u32) -> String {
        format!("{ROOT}/{}/robot/{k}/stats", self.fleet)
    }

    /// `echelon/<fleet>/alive/<role>`.
    pub fn alive(&self, role: &str) -> String {
        format!("{ROOT}/{}/alive/{role}", self.fleet)
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
        if rest == "reference" {
            return KeyKind::Reference;
        }
        let parts: Vec<&str> = rest.split('/').collect();
        if let ["robot", num, what] = parts[..]
            && let Ok(k) = num.parse::<u32>()
            && k >= 1
            && k.to_string() == num
        {
            return match what {
                "state" => KeyKind::State(k),
                "stats" => KeyKind::Stats(k),
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
    }
}
