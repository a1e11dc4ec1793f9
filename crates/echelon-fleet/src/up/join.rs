//! Hub mode's wait: the reference starts only once every robot of the
//! scenario has joined (its liveliness token `alive/robot/<k>` reached the
//! hub's router), with a progress line for the operator — who joined, from
//! which host and address (its [probe](crate::probe)), who is still missing
//! and where each is placed — and a bounded wait (`--wait`) that ends
//! naming the missing robots.

use std::collections::BTreeMap;
use std::time::{Duration, Instant};

use echelon::scenario::Placement;

use crate::keys::Keys;
use crate::net::NetOptions;
use crate::role::Member;
use crate::{FleetError, StopFlag};

/// How often the progress line is repeated while nobody new joins.
const PROGRESS_EVERY: Duration = Duration::from_secs(5);

/// Who is awaited: agent `k` and where its process runs.
pub(super) type Awaited = Vec<(u32, Placement)>;

/// A joined robot's name as the operator reads it: `robot/3 (on-board, host
/// pi-3, 192.168.1.23)`.
fn describe(k: u32, placement: Placement, who: Option<&crate::probe::ProbeAnswer>) -> String {
    let place = match placement {
        Placement::Hub => "on the hub",
        Placement::Onboard => "on-board",
    };
    let mut s = format!("{} ({place}", Member::Robot(k).liveliness());
    if let Some(a) = who {
        s.push_str(&format!(", host {}", a.host));
        if let Some(addr) = &a.address {
            s.push_str(&format!(", from {addr}"));
        }
        if a.version != crate::probe::VERSION {
            s.push_str(&format!(
                ", echelon {} (the hub runs {})",
                a.version,
                crate::probe::VERSION
            ));
        }
    }
    s.push(')');
    s
}

/// Waits until every awaited robot's token is on the hub's router (through
/// a session of `net`, the hub's own link), printing who joins; fails with
/// [`FleetError::TimedOut`] naming the missing robots after `wait`, and
/// returns at once when `stop` is raised. `check` runs every turn (the
/// hub's own processes still alive).
pub(super) fn wait_for_robots(
    net: &NetOptions,
    keys: &Keys,
    awaited: &Awaited,
    wait: Duration,
    stop: &StopFlag,
    check: &mut dyn FnMut() -> Result<(), FleetError>,
) -> Result<(), FleetError> {
    let session = crate::net::open(net)?;
    let tokens = crate::runtime::Tokens::watch(&session, &keys.alive("robot/*"))?;
    let started = Instant::now();
    let mut announced: BTreeMap<u32, bool> = BTreeMap::new();
    let mut last_line = Instant::now();
    eprintln!(
        "fleet up: waiting for {} robot(s) to join (at most {:.0} s): {}",
        awaited.len(),
        wait.as_secs_f64(),
        awaited
            .iter()
            .map(|&(k, p)| describe(k, p, None))
            .collect::<Vec<_>>()
            .join(", ")
    );
    loop {
        check()?;
        let present = tokens.present()?;
        let mut missing = Vec::new();
        for &(k, placement) in awaited {
            let here = present.contains(&keys.alive(&Member::Robot(k).liveliness()));
            let was = announced.get(&k).copied().unwrap_or(false);
            if here && !was {
                let who = ask_who(&session, keys, k);
                let left = awaited.len() - present.len().min(awaited.len());
                eprintln!(
                    "fleet up: {} joined after {:.1} s ({left} to go)",
                    describe(k, placement, who.as_ref()),
                    started.elapsed().as_secs_f64()
                );
                last_line = Instant::now();
            } else if !here && was {
                eprintln!(
                    "fleet up: {} left before the start",
                    describe(k, placement, None)
                );
            }
            announced.insert(k, here);
            if !here {
                missing.push(describe(k, placement, None));
            }
        }
        if missing.is_empty() {
            // Let the declarations that came with the tokens settle.
            std::thread::sleep(Duration::from_millis(100));
            return Ok(());
        }
        if stop.is_raised() {
            return Ok(());
        }
        if started.elapsed() > wait {
            return Err(FleetError::TimedOut(format!(
                "fleet up --hub: waited {:.0} s; {} never joined (start each on its computer: `echelon fleet robot --config robot-K/robot.toml`, from `echelon fleet bundle`; or raise --wait)",
                wait.as_secs_f64(),
                missing.join(", ")
            )));
        }
        if last_line.elapsed() > PROGRESS_EVERY {
            eprintln!(
                "fleet up: {} of {} joined; waiting for {} ({:.0} s of {:.0})",
                awaited.len() - missing.len(),
                awaited.len(),
                missing.join(", "),
                started.elapsed().as_secs_f64(),
                wait.as_secs_f64()
            );
            last_line = Instant::now();
        }
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// Robot `k`'s probe answer (who it is, where from), if it answers soon.
fn ask_who(session: &zenoh::Session, keys: &Keys, k: u32) -> Option<crate::probe::ProbeAnswer> {
    crate::probe::ask(
        session,
        keys,
        &Member::Robot(k).liveliness(),
        1,
        Duration::ZERO,
        Duration::from_millis(500),
    )
    .ok()
    .and_then(|s| s.answer)
}
