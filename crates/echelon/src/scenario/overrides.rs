//! Command-line overrides of a scenario's settings, applied to the parsed
//! document before it is built (as openrr's config overwrite does), with a
//! record of which flag set which field so that errors name the flag.

use std::fmt;

use super::locate::{FieldPath, Origins};
use super::schema::ScenarioFile;
use crate::control::Variant;

/// Command-line style overrides of a scenario's settings.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Overrides {
    /// RK4 step, s.
    pub dt: Option<f64>,
    /// Simulated time, s.
    pub duration: Option<f64>,
    /// Logging period, s (0: every step).
    pub log_dt: Option<f64>,
    /// Law variant for every agent.
    pub law: Option<Variant>,
    /// Seed of the random models.
    pub seed: Option<u64>,
}

impl Overrides {
    /// Writes the overrides into `file` and returns which fields they set.
    pub(crate) fn apply(&self, file: &mut ScenarioFile) -> Origins {
        let mut origins = Origins::new();
        let mut set = |path: &str, flag: &'static str| origins.push((FieldPath::from(path), flag));
        if let Some(dt) = self.dt {
            file.sim.dt = dt;
            set("sim.dt", "--dt");
        }
        if let Some(duration) = self.duration {
            file.sim.duration = duration;
            set("sim.duration", "--duration");
        }
        if let Some(log_dt) = self.log_dt {
            file.log.dt = Some(log_dt);
            set("log.dt", "--log-dt");
        }
        if let Some(law) = self.law {
            file.control.law = Some(law.into());
            for a in &mut file.agents {
                if let Some(c) = &mut a.control {
                    c.law = None;
                }
            }
            set("control.law", "--law");
        }
        if let Some(seed) = self.seed {
            file.seed = Some(seed);
            set("seed", "--seed");
        }
        origins
    }
}

impl fmt::Display for Overrides {
    /// The overrides as `echelon run` flags (`--dt 0.002 --law complete`), or `none`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let mut flags = Vec::new();
        for (flag, v) in [
            ("--dt", self.dt),
            ("--duration", self.duration),
            ("--log-dt", self.log_dt),
        ] {
            if let Some(v) = v {
                flags.push(format!("{flag} {v}"));
            }
        }
        if let Some(seed) = self.seed {
            flags.push(format!("--seed {seed}"));
        }
        if let Some(law) = self.law {
            flags.push(match law {
                Variant::Paper => "--law paper".to_owned(),
                Variant::Complete => "--law complete".to_owned(),
            });
        }
        if flags.is_empty() {
            f.write_str("none")
        } else {
            f.write_str(&flags.join(" "))
        }
    }
}
