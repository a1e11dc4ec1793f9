//! An agent's odometry: the `[odometry]` section's error model, fusion and
//! fix schedule.

use crate::check;
use crate::error::ScenarioError;
use crate::odometry::{ErrorModel, FixSchedule, FixSpec, Fusion, OdometrySpec, ZetaModel};
use crate::plan::Timing;
use crate::scenario::locate::FieldPath;
use crate::scenario::merge::Merge;
use crate::scenario::schema::{AgentSection, FixesSection, OdometrySection};

use super::Builder;

impl Builder<'_> {
    /// Agent `i`'s odometry: its own `odometry`/`fixes` over the file's, field by
    /// field; `None` when neither asks for odometry (or `enabled = false`).
    pub(super) fn odometry(
        &self,
        i: usize,
        a: &AgentSection,
        dt: f64,
        timing: &Timing,
    ) -> Result<Option<OdometrySpec>, ScenarioError> {
        let f = self.file;
        let agent = FieldPath::from("agents").index(i);
        let odo = Merge::new(
            a.odometry.as_ref(),
            f.odometry.as_ref(),
            agent.key("odometry"),
            FieldPath::from("odometry"),
        );
        let fix = Merge::new(
            a.fixes.as_ref(),
            f.fixes.as_ref(),
            agent.key("fixes"),
            FieldPath::from("fixes"),
        );
        let odometry_off = odo.get(|s| s.enabled, "enabled").filter(|(e, _)| !e);
        let fixes_on = fix.any() && fix.get(|s| s.enabled, "enabled").is_none_or(|(e, _)| e);
        if let Some((_, path)) = odometry_off {
            // Global fixes simply do not apply; the agent's own would contradict.
            if fixes_on && a.fixes.is_some() {
                return Err(self.at.error(
                    &path,
                    "fixes correct an odometry estimate, but this agent's odometry is disabled",
                ));
            }
            return Ok(None);
        }
        if !odo.any() && !fixes_on {
            return Ok(None);
        }
        // The sampling period, and whether it is the step's (a fixes' period
        // must be a multiple of it: a refusal then may be the step's fault).
        let (period, is_step) = match odo.get(|s| s.period, "period") {
            None => match timing {
                Timing::Sampled { period } => (*period, false),
                Timing::Continuous => (dt, true),
            },
            Some((p, path)) => {
                check::multiple_of("period", p, dt, "dt")
                    .map_err(|e| self.against_step(&path, &e))?;
                (p, false)
            }
        };
        let num = |get: fn(&OdometrySection) -> Option<f64>, key: &str, default: f64| {
            odo.get(get, key).map_or(default, |(v, _)| v)
        };
        let zeta_model = odo
            .get(|s| s.zeta_model, "zeta_model")
            .map_or(ZetaModel::Wheels, |(m, _)| m);
        let ticks = odo
            .get(|s| s.ticks_per_rev, "ticks_per_rev")
            .map(|(v, _)| v);
        let errors = ErrorModel::PERFECT
            .with_zeta(num(|s| s.zeta, "zeta", 0.0), zeta_model)
            .and_then(|e| {
                e.with_systematic(
                    num(|s| s.wheel_diameter_ratio, "wheel_diameter_ratio", 1.0),
                    num(|s| s.wheelbase_ratio, "wheelbase_ratio", 1.0),
                )
            })
            .and_then(|e| e.with_slip(num(|s| s.slip, "slip", 0.0)))
            .and_then(|e| e.with_ticks_per_rev(ticks))
            .and_then(|e| {
                e.with_speed_noise(
                    num(|s| s.speed_noise, "speed_noise", 0.0),
                    num(|s| s.turn_rate_noise, "turn_rate_noise", 0.0),
                )
            })
            .map_err(|e| self.at.param(&odo.path_of(e.field), &e))?;
        let fixes = if fixes_on {
            Some(self.fixes(&fix, period, is_step)?)
        } else {
            None
        };
        let spec = OdometrySpec::new(period, errors, fixes);
        Ok(Some(self.at(&odo.table_path(), spec)?))
    }

    /// The fixes that apply to one agent, sampled every `period` seconds
    /// (`is_step`: the step `sim.dt`).
    fn fixes(
        &self,
        fix: &Merge<'_, FixesSection>,
        period: f64,
        is_step: bool,
    ) -> Result<FixSpec, ScenarioError> {
        let schedule = match (
            fix.get(|s| s.every_steps, "every_steps"),
            fix.get(|s| s.period, "period"),
        ) {
            (Some(_), Some((_, path))) => {
                return Err(self
                    .at
                    .error(&path, "give either every_steps or period, not both"));
            }
            (None, None) => {
                return Err(self.at.error(
                    &fix.table_path(),
                    "missing field `every_steps` (samples between fixes) or `period` (s)",
                ));
            }
            (Some((n, _)), None) => FixSchedule::EverySamples(n),
            (None, Some((p, _))) => FixSchedule::Period(p),
        };
        let value =
            |get: fn(&FixesSection) -> Option<f64>, key: &str| fix.get(get, key).map(|(v, _)| v);
        let fusion = fix
            .get(|s| s.fusion, "fusion")
            .map_or(Fusion::Reset, |(f, _)| f);
        let spec = FixSpec::new(schedule, fusion)
            .and_then(|f| {
                f.with_noise(
                    value(|s| s.position_noise, "position_noise").unwrap_or(0.0),
                    value(|s| s.heading_noise, "heading_noise"),
                )
            })
            .and_then(|f| f.with_latency(value(|s| s.latency, "latency").unwrap_or(0.0)))
            .map_err(|e| self.at.param(&fix.path_of(e.field), &e))?;
        spec.samples_between(period).map_err(|e| {
            let path = fix.path_of(e.field);
            if is_step {
                self.against_step(&path, &e)
            } else {
                self.at.param(&path, &e)
            }
        })?;
        Ok(spec)
    }
}
