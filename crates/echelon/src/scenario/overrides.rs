//! Command-line overrides of a scenario's settings, applied to the parsed
//! document before it is built (as openrr's config overwrite does), with a
//! record of which flag set which field so that errors name the flag.

use std::fmt;

use super::Scenario;
use super::locate::{FieldPath, Origins};
use super::schema::{FixesSection, OdometrySection, ScenarioFile};
use crate::control::Variant;
use crate::odometry::ZetaModel;

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

/// An odometry error model and fix interval written over the `[odometry]` and
/// `[fixes]` of a scenario and of each agent that has its own (`echelon
/// sweep`'s grid; the file's other odometry settings — period, ticks, noise,
/// fix noise — are kept). A value refused names its flag.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OdometryOverrides {
    /// `ζ`, m per sample (`--zeta`).
    pub zeta: f64,
    /// How `ζ` enters (`--zeta-model`).
    pub zeta_model: ZetaModel,
    /// `E_d` (`--ed`).
    pub wheel_diameter_ratio: f64,
    /// `E_b` (`--eb`).
    pub wheelbase_ratio: f64,
    /// Slip variance, m²/m (`--slip`).
    pub slip: f64,
    /// Odometry samples between absolute fixes, 0: no fixes (`--fix-every`).
    pub fix_every: u64,
}

impl OdometryOverrides {
    /// Each field with the `echelon sweep` flag that sets it, in the order
    /// of the struct: the odometry fields (also the `[odometry]` keys they
    /// are written to), then `fix_every`. The one table of these names
    /// ([`crate::sweep::GridSpec::flag`] reads it too).
    pub const FLAGS: [(&'static str, &'static str); 6] = [
        ("zeta", "--zeta"),
        ("zeta_model", "--zeta-model"),
        ("wheel_diameter_ratio", "--ed"),
        ("wheelbase_ratio", "--eb"),
        ("slip", "--slip"),
        ("fix_every", "--fix-every"),
    ];

    fn odometry(&self, o: &mut OdometrySection) {
        o.zeta = Some(self.zeta);
        o.zeta_model = Some(self.zeta_model);
        o.wheel_diameter_ratio = Some(self.wheel_diameter_ratio);
        o.wheelbase_ratio = Some(self.wheelbase_ratio);
        o.slip = Some(self.slip);
    }

    /// Sets the fixes; returns the field set.
    fn fixes(&self, f: &mut FixesSection) -> &'static str {
        if self.fix_every == 0 {
            f.enabled = Some(false);
            "enabled"
        } else {
            f.enabled = None;
            f.every_steps = Some(self.fix_every);
            f.period = None;
            "every_steps"
        }
    }
}

impl Scenario {
    /// This scenario with `o` written over its odometry and fixes.
    pub fn with_odometry(&self, o: &OdometryOverrides) -> Scenario {
        let mut s = self.clone();
        let f = &mut s.file;
        o.odometry(f.odometry.get_or_insert_with(Default::default));
        let fixes_key = o.fixes(f.fixes.get_or_insert_with(Default::default));
        let mut odometry_at = vec![FieldPath::from("odometry")];
        let mut fixes_at = vec![FieldPath::from("fixes")];
        for (i, a) in f.agents.iter_mut().enumerate() {
            let agent = FieldPath::from("agents").index(i);
            if let Some(odometry) = &mut a.odometry {
                o.odometry(odometry);
                odometry_at.push(agent.key("odometry"));
            }
            if let Some(fixes) = &mut a.fixes {
                o.fixes(fixes);
                fixes_at.push(agent.key("fixes"));
            }
        }
        let [odometry_flags @ .., (_, fix_flag)] = &OdometryOverrides::FLAGS;
        for table in odometry_at {
            for &(key, flag) in odometry_flags.iter() {
                s.flags.push((table.key(key), flag));
            }
        }
        for table in fixes_at {
            s.flags.push((table.key(fixes_key), *fix_flag));
        }
        s
    }
}
