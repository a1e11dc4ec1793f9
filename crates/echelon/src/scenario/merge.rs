//! Per-agent defaults: an agent's own table (`control`, `odometry`, `fixes`,
//! `link_loss`) over the file's, field by field, each value with the path it
//! was set at (or would be set at, for a default).

use super::locate::FieldPath;

/// An agent's table over the file's, field by field, remembering where each
/// value came from.
pub(super) struct Merge<'a, S> {
    own: Option<&'a S>,
    global: Option<&'a S>,
    own_path: FieldPath,
    global_path: FieldPath,
}

impl<'a, S: serde::Serialize> Merge<'a, S> {
    pub(super) fn new(
        own: Option<&'a S>,
        global: Option<&'a S>,
        own_path: FieldPath,
        global_path: FieldPath,
    ) -> Self {
        Merge {
            own,
            global,
            own_path,
            global_path,
        }
    }

    /// Whether either table exists.
    pub(super) fn any(&self) -> bool {
        self.own.is_some() || self.global.is_some()
    }

    /// The value of `key` and the path it was set at.
    pub(super) fn get<T>(&self, get: fn(&S) -> Option<T>, key: &str) -> Option<(T, FieldPath)> {
        if let Some(v) = self.own.and_then(get) {
            return Some((v, self.own_path.key(key)));
        }
        self.global
            .and_then(get)
            .map(|v| (v, self.global_path.key(key)))
    }

    /// [`Merge::get`], else `default` (at the file's path, where it would be set).
    pub(super) fn get_or<T>(
        &self,
        get: fn(&S) -> Option<T>,
        key: &str,
        default: T,
    ) -> (T, FieldPath) {
        self.get(get, key)
            .unwrap_or_else(|| (default, self.global_path.key(key)))
    }

    /// Where `key` is set: the agent's table if it sets it, else the file's.
    pub(super) fn path_of(&self, key: &str) -> FieldPath {
        let sets = self
            .own
            .and_then(|s| toml::Table::try_from(s).ok())
            .is_some_and(|t| t.contains_key(key));
        if sets {
            self.own_path.key(key)
        } else {
            self.global_path.key(key)
        }
    }

    /// The table that applies (the agent's if it has one).
    pub(super) fn table_path(&self) -> FieldPath {
        if self.own.is_some() {
            self.own_path.clone()
        } else {
            self.global_path.clone()
        }
    }
}
