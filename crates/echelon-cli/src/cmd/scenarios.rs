//! `echelon scenarios` and `echelon show`.

use anyhow::{Result, bail};

use super::out::{out, outln};
use echelon::scenario::{self, Scenario};

/// Arguments of `echelon show`.
#[derive(Debug, clap::Args)]
pub(crate) struct ShowArgs {
    /// Built-in scenario name (see `echelon scenarios`).
    name: String,
}

/// Lists the built-ins, one line each.
pub(crate) fn list() -> Result<()> {
    for (name, _) in scenario::builtin() {
        let description = Scenario::builtin(name)
            .and_then(|s| s.file.description.clone())
            .unwrap_or_default();
        outln!("{name:<24} {description}")?;
    }
    Ok(())
}

/// Prints a built-in's TOML exactly as shipped.
pub(crate) fn show(args: &ShowArgs) -> Result<()> {
    match scenario::builtin().iter().find(|(n, _)| *n == args.name) {
        Some((_, src)) => {
            out!("{src}")?;
            Ok(())
        }
        None => {
            let names: Vec<&str> = scenario::builtin().iter().map(|(n, _)| *n).collect();
            bail!(
                "no built-in scenario `{}` (built-ins: {})",
                args.name,
                names.join(", ")
            )
        }
    }
}
