//! `echelon fleet status`: the running fleet seen from any machine that
//! reaches its hub (`echelon_fleet::status`): a table, or JSON; once, or
//! every second with `--watch`.

use std::io::IsTerminal;
use std::time::{Duration, Instant};

use anyhow::Result;

use echelon::scenario::Scenario;
use echelon_fleet::role::Member;
use echelon_fleet::status::{FleetStatus, Listener, StatusOptions};
use echelon_fleet::{FleetError, StopFlag};

use super::operator_args::StatusArgs;
use crate::cmd::out::{Failed, out, outln};

/// How often `--watch` redraws.
const REFRESH: Duration = Duration::from_secs(1);

/// Sleeps until `deadline` or until `stop` is raised.
fn sleep_until(deadline: Instant, stop: &StopFlag) {
    while !stop.is_raised() {
        let left = deadline.saturating_duration_since(Instant::now());
        if left.is_zero() {
            return;
        }
        std::thread::sleep(left.min(Duration::from_millis(50)));
    }
}

/// Prints one refresh: JSON on one line, or the table (redrawn in place
/// on a terminal with `--watch`, else after a blank line).
fn print(status: &FleetStatus, a: &StatusArgs, first: bool) -> Result<()> {
    if a.json {
        return outln!("{}", serde_json::to_string(status)?);
    }
    if a.watch && std::io::stdout().is_terminal() {
        out!("\x1b[H\x1b[2J")?;
    } else if !first {
        outln!("")?;
    }
    out!("{status}")
}

/// `fleet status`: listens for `--listen-for` s, prints what it heard,
/// and with `--watch` goes on every second until SIGINT/SIGTERM. Fails
/// (exit 1) when no robot of the fleet was heard in the first listening.
pub(super) fn status_cmd(a: StatusArgs) -> Result<()> {
    let scenario = a.scenario.as_deref().map(Scenario::resolve).transpose()?;
    let fleet = a.net.fleet_name(scenario.as_ref())?;
    let robots = scenario.as_ref().map(super::agents_of).transpose()?;
    let net = super::session(&a.net, Member::Operator, scenario.as_ref())?;
    let listen = Duration::from_secs_f64(a.listen_for);
    let at = if net.connect.is_empty() {
        "this machine (no --connect ENDPOINT given)".to_owned()
    } else {
        net.connect.join(", ")
    };
    let nobody = |why: &str| {
        Failed(format!(
            "no robot of fleet `{fleet}` heard at {at} within {} s{why} (is the fleet running? give its hub's endpoint: --hub ENDPOINT, as `fleet up` printed it)",
            a.listen_for
        ))
    };
    let stop = StopFlag::on_signals()?;
    let listener = match Listener::join(&StatusOptions {
        fleet: fleet.clone(),
        net,
        robots: robots.unwrap_or(0),
        connect_timeout: listen,
    }) {
        Ok(l) => l,
        // The endpoints did not answer within the listening time, or Zenoh
        // refused (its message without the source location it appends).
        Err(FleetError::TimedOut(e) | FleetError::Zenoh(e)) => {
            let e = e.split(" at /").next().unwrap_or_default();
            return Err(nobody(&format!(": {e}")).into());
        }
        Err(e) => return Err(e.into()),
    };
    sleep_until(Instant::now() + listen, &stop);
    let mut first = true;
    let result = loop {
        let status = listener.status();
        if first && !status.heard_a_robot() {
            break Err(nobody("").into());
        }
        if let Err(e) = print(&status, &a, first) {
            break Err(e);
        }
        first = false;
        if !a.watch || stop.is_raised() {
            break Ok(());
        }
        sleep_until(Instant::now() + REFRESH, &stop);
        if stop.is_raised() {
            break Ok(());
        }
    };
    listener.close();
    result
}
