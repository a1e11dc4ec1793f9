//! `echelon fleet doctor`: the checks of `echelon_fleet::doctor` before a
//! run, printed as a table (or JSON with `--json`); exit 1 when one fails.

use std::time::Duration;

use anyhow::Result;

use echelon::scenario::Scenario;
use echelon_fleet::doctor::{self, DoctorOptions};
use echelon_fleet::role::Member;

use super::operator_args::DoctorArgs;
use crate::cmd::out::{Failed, out, outln};

/// `fleet doctor`: reaches the hub (`--hub`, or `--connect`) as the
/// operator, checks, prints; fails (exit 1) naming the failed checks.
pub(super) fn doctor_cmd(a: DoctorArgs) -> Result<()> {
    let scenario = Scenario::resolve(&a.scenario)?;
    let net = super::session(&a.net, Member::Operator, Some(&scenario))?;
    let secure = net.secure.clone();
    let hub = (!net.connect.is_empty()).then_some(net);
    let report = doctor::run(&DoctorOptions {
        scenario,
        fleet: a.net.fleet.clone(),
        hub,
        secure,
        listen_for: Duration::from_secs_f64(a.listen_for),
        timeout: Duration::from_secs_f64(a.timeout),
    })?;
    if a.json {
        outln!("{}", serde_json::to_string_pretty(&report)?)?;
    } else {
        out!("{}", report.table())?;
    }
    if report.ok {
        return Ok(());
    }
    let failed: Vec<String> = report
        .failed()
        .map(|r| format!("{} {}", r.subject, r.check))
        .collect();
    Err(Failed(format!(
        "fleet doctor: {} check{} failed: {}",
        failed.len(),
        if failed.len() == 1 { "" } else { "s" },
        failed.join(", ")
    ))
    .into())
}
