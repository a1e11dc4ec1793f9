//! What every fleet process that runs on a clock is started with (the
//! leader, a robot, a simulated base), and the one place that turns it into
//! the scenario's plan, its `[fleet]` settings, the fleet's keys and the
//! clock.

use echelon::plan::Plan;
use echelon::scenario::{FleetSettings, Overrides, Scenario};

use crate::FleetError;
use crate::clock::FleetClock;
use crate::keys::Keys;
use crate::net::NetOptions;

/// A fleet process's scenario, clock and network.
#[derive(Debug, Clone)]
pub struct ProcessOptions {
    /// The scenario.
    pub scenario: Scenario,
    /// Clock speed-up `K` ([`FleetClock`]).
    pub time_scale: f64,
    /// Stop at this fleet time, s (absent: the leader stops at the
    /// scenario's `sim.duration`, a robot or a base at a signal).
    pub duration: Option<f64>,
    /// Network.
    pub net: NetOptions,
    /// Fleet name, the second chunk of every key (absent: the scenario's).
    pub fleet: Option<String>,
    /// The process kills itself with SIGKILL at this fleet time (`--die-at`:
    /// the fault matrix's `kill -9`, [`crate::faults::die_if_due`]).
    pub die_at: Option<f64>,
}

/// [`ProcessOptions`]' scenario, built once.
#[derive(Debug, Clone)]
pub struct Resolved {
    /// The scenario's plan.
    pub plan: Plan,
    /// Its `[fleet]` settings.
    pub settings: FleetSettings,
    /// The fleet's keys (under the `fleet` name if given, else the scenario's).
    pub keys: Keys,
}

impl ProcessOptions {
    /// Builds the scenario's plan and `[fleet]` settings (once) and the
    /// fleet's keys.
    pub fn resolve(&self) -> Result<Resolved, FleetError> {
        let settings = self.scenario.fleet()?;
        let plan = self.scenario.build(&Overrides::default())?.plan;
        let keys = Keys::new(self.fleet.as_deref().unwrap_or(&settings.name));
        Ok(Resolved {
            plan,
            settings,
            keys,
        })
    }

    /// The process's clock, `time_scale` times faster than real time.
    pub fn clock(&self) -> FleetClock {
        FleetClock::new(self.time_scale)
    }
}
