//! The rows of what the probes measured: the hub's router's and each
//! robot process's version, clock offset and round trips.

use std::time::Duration;

use echelon::scenario::Placement;

use super::report::{Row, Status};
use super::{CLOCK_FAIL, CLOCK_WARN, LOSS_FAIL, PROBE_INTERVAL, RTT_FAIL, RTT_WARN, ms};
use crate::keys::Keys;
use crate::probe::{self, ProbeStats};

/// The round trips' row of `subject`, judged against the scenario's
/// `link_timeout` (s).
pub(super) fn round_trip_row(subject: &str, p: &ProbeStats, link_timeout: f64) -> Row {
    let (p50, p99) = (p.rtt_p50.unwrap_or(0.0), p.rtt_p99.unwrap_or(0.0));
    let (warn, fail) = (RTT_WARN * link_timeout, RTT_FAIL * link_timeout);
    let status = if p.loss > LOSS_FAIL || p99 > fail {
        Status::Fail
    } else if p.loss > 0.0 || p99 > warn {
        Status::Warn
    } else {
        Status::Pass
    };
    Row::new(
        subject,
        "round trip",
        status,
        format!(
            "p50 {}, p99 {}, loss {:.0} %",
            ms(p50),
            ms(p99),
            p.loss * 100.0
        ),
        format!(
            "{} of {} probes answered (one every {:.0} ms); p99 warns above {} or at any loss, fails above {} (link_timeout {}) or {:.0} % lost",
            p.answered,
            p.rounds,
            PROBE_INTERVAL.as_secs_f64() * 1e3,
            ms(warn),
            ms(fail),
            ms(link_timeout),
            LOSS_FAIL * 100.0
        ),
    )
}

/// The version row of `subject`, whose answer is `p`'s.
pub(super) fn version_row(subject: &str, p: &ProbeStats) -> Option<Row> {
    let a = p.answer.as_ref()?;
    if a.version == probe::VERSION {
        return Some(Row::new(
            subject,
            "version",
            Status::Pass,
            &a.version,
            "the same echelon as this doctor",
        ));
    }
    Some(Row::new(
        subject,
        "version",
        Status::Fail,
        &a.version,
        format!(
            "{} runs echelon {}, this doctor {}: install one version everywhere",
            a.member,
            a.version,
            probe::VERSION
        ),
    ))
}

/// The hub's rows from its router's probe.
pub(super) fn hub_rows(
    p: Option<&ProbeStats>,
    keys: &Keys,
    timeout: Duration,
    link_timeout: f64,
) -> Vec<Row> {
    let Some(p) = p.filter(|p| p.answered > 0) else {
        return vec![Row::new(
            "hub",
            "router probe",
            Status::Fail,
            "no answer",
            format!(
                "no router answered on {} within {:.1} s: is the hub's router echelon's (`fleet router`, `fleet up`), of this version?",
                keys.probe("router"),
                timeout.as_secs_f64()
            ),
        )];
    };
    let mut rows = Vec::new();
    if let Some(a) = &p.answer {
        rows.push(Row::new(
            "hub",
            "router probe",
            Status::Pass,
            &a.host,
            format!("pid {}, zenoh id {}", a.pid, a.zid),
        ));
    }
    rows.extend(version_row("hub", p));
    if let Some(o) = p.offset {
        // This machine's clock is not the fleet's: off, it only warns.
        let (status, advice) = match o.abs() > CLOCK_WARN {
            true => (
                Status::Warn,
                ": this machine's clock is off (the robots' offsets are still the hub's)",
            ),
            false => (Status::Pass, ""),
        };
        rows.push(Row::new(
            "hub",
            "clock offset",
            status,
            format!("{:+.1} ms", o * 1e3),
            format!(
                "the hub's wall clock minus this machine's (± {}); the robots are judged against the hub's{advice}",
                ms(p.rtt_p50.unwrap_or(0.0) / 2.0)
            ),
        ));
    }
    rows.push(round_trip_row("hub", p, link_timeout));
    rows
}

/// Robot `subject`'s process rows from its probe `p` (`None`: not asked,
/// no hub), `hub` its offset and round trip when the hub answered.
pub(super) fn process_rows(
    subject: &str,
    p: Option<&ProbeStats>,
    asked: bool,
    placement: Placement,
    hub: Option<(f64, f64)>,
    link_timeout: f64,
) -> Vec<Row> {
    let Some(p) = p.filter(|p| p.answered > 0) else {
        let row = Row::new(subject, "robot process", Status::Info, "not running", "");
        return vec![match (asked, placement) {
            (false, _) => Row {
                value: "not checked".into(),
                detail: "give --hub ENDPOINT to probe it".into(),
                ..row
            },
            (true, Placement::Onboard) => Row {
                status: Status::Fail,
                detail: "placement = \"onboard\": its process must run on the robot and join the hub before the run (`echelon fleet robot --config robot.toml` there)".into(),
                ..row
            },
            (true, Placement::Hub) => Row {
                detail: "placement = \"hub\": `fleet up` starts it on the hub".into(),
                ..row
            },
        }];
    };
    let mut rows = Vec::new();
    if let Some(a) = &p.answer {
        rows.push(Row::new(
            subject,
            "robot process",
            Status::Pass,
            &a.host,
            format!("running, pid {}, zenoh id {}", a.pid, a.zid),
        ));
    }
    rows.extend(version_row(subject, p));
    if let Some(offset) = p.offset {
        let half_rtt = p.rtt_p50.unwrap_or(0.0) / 2.0;
        let (offset, against, err) = match hub {
            Some((hub, hub_rtt)) => (offset - hub, "the hub's", half_rtt + hub_rtt / 2.0),
            None => (
                offset,
                "this machine's (the hub's router did not answer)",
                half_rtt,
            ),
        };
        let status = if offset.abs() > CLOCK_FAIL {
            Status::Fail
        } else if offset.abs() > CLOCK_WARN {
            Status::Warn
        } else {
            Status::Pass
        };
        let advice = match status {
            Status::Pass => "",
            _ => ": synchronise it with chrony (docs/real-robots.md, \"Stamps and clocks\")",
        };
        rows.push(Row::new(
            subject,
            "clock offset",
            status,
            format!("{:+.1} ms", offset * 1e3),
            format!(
                "its wall clock minus {against} (± {}), the median of {} round trips; warn above {}, fail above {}{advice}",
                ms(err),
                p.answered,
                ms(CLOCK_WARN),
                ms(CLOCK_FAIL)
            ),
        ));
    }
    rows.push(round_trip_row(subject, p, link_timeout));
    rows
}
