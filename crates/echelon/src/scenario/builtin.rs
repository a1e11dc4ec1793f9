//! The scenarios built into echelon (`scenarios/*.toml`, embedded at build time)
//! and finding a scenario by built-in name or path.

use std::path::Path;

use super::Scenario;
use super::locate::whole_file_error;
use crate::error::ScenarioError;

include!(concat!(env!("OUT_DIR"), "/builtin.rs"));

/// The scenarios built into echelon, as `(name, TOML source)`, from `scenarios/*.toml`.
pub fn builtin() -> &'static [(&'static str, &'static str)] {
    BUILTIN
}

impl Scenario {
    /// A built-in scenario by name.
    pub fn builtin(name: &str) -> Option<Scenario> {
        let (_, src) = BUILTIN.iter().find(|(n, _)| *n == name)?;
        Scenario::parse(src, &format!("builtin:{name}"), None).ok()
    }

    /// A built-in name, or a path to a `.toml` file (anything with a `.toml`
    /// extension or a path separator is taken as a path).
    pub fn resolve(name_or_path: &str) -> Result<Scenario, ScenarioError> {
        let is_path = name_or_path.ends_with(".toml")
            || name_or_path.contains('/')
            || name_or_path.contains(std::path::MAIN_SEPARATOR);
        if is_path {
            return Scenario::load(Path::new(name_or_path));
        }
        Scenario::builtin(name_or_path).ok_or_else(|| {
            let names: Vec<&str> = BUILTIN.iter().map(|(n, _)| *n).collect();
            whole_file_error(
                name_or_path,
                format!(
                    "no built-in scenario of that name (built-ins: {}; a file path must end in .toml)",
                    names.join(", ")
                ),
            )
        })
    }
}
