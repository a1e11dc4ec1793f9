//! `echelon fleet stop` and `echelon fleet resume`: a short-lived process,
//! the fleet's `operator`, that puts one fleet command
//! ([`crate::command`]) and waits until every robot alive acknowledges it.
//!
//! In order: which robots are alive (their liveliness tokens,
//! `alive/robot/<k>`); the highest command number the fleet's latches
//! answer (the command is numbered one past it, so a resume lifts every
//! stop issued before it); the put on `echelon/<fleet>/command`; then the
//! latches asked every [`POLL`] until each live robot answers with this
//! order at this number or later, or `timeout` passes. A robot
//! acknowledges once it obeys: a stopped robot has commanded zero when it
//! answers.
//!
//! A resume is signed with the operator token ([`crate::token`]) and is not
//! put without one ([`NEEDS_TOKEN`]); a robot that refuses it (no valid
//! proof of its own token, or no token at all) says so in its latch answer
//! ([`Latched::refused`]), and the report names it ([`refusals`]). A stop
//! needs no token.

use std::collections::{BTreeMap, BTreeSet};
use std::time::{Duration, Instant};

use serde::{Deserialize, Serialize};
use zenoh::Wait;

use crate::command::{FleetCommand, Latched, Order};
use crate::keys::Keys;
use crate::net::{self, NetOptions};
use crate::role::{Member, Role};
use crate::runtime;
use crate::token::OperatorToken;
use crate::{FleetError, StopFlag};

/// Why a resume is not put without the operator token.
pub const NEEDS_TOKEN: &str = "fleet resume needs the operator token: give --token-file OUT/operator-token (written by fleet up), --token, or ECHELON_OPERATOR_TOKEN";

/// How often the latches are asked for acknowledgements, real time.
pub const POLL: Duration = Duration::from_millis(20);
/// How long the leader's acknowledgement is awaited once every robot's is
/// in (it is for the report only).
const LEADER_GRACE: Duration = Duration::from_millis(250);
/// How long the liveliness tokens and the first latch answers are awaited.
const ASK: Duration = Duration::from_millis(1000);

/// Options of `fleet stop` / `fleet resume`.
#[derive(Debug, Clone)]
pub struct OperatorOptions {
    /// The fleet.
    pub fleet: String,
    /// Stop or resume.
    pub order: Order,
    /// Why (in the command and the logs).
    pub reason: String,
    /// Longest wait for the acknowledgements, real time.
    pub timeout: Duration,
    /// Network.
    pub net: NetOptions,
    /// The fleet's operator token, which signs a resume (a resume without
    /// one is refused before anything is put; a stop needs none).
    pub token: Option<OperatorToken>,
}

/// One robot's acknowledgement.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Ack {
    /// Its liveliness name (`robot/<k>`).
    pub robot: String,
    /// Seconds from the put to the answer that acknowledged it (real time;
    /// an upper bound on when the robot obeyed).
    pub after: f64,
}

/// What `fleet stop` / `fleet resume` reports (one JSON line on stdout).
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OperatorReport {
    /// [`Role::Operator`].
    pub role: Role,
    /// The command put.
    pub command: FleetCommand,
    /// When it was put, UNIX ns.
    pub published_unix_ns: u64,
    /// The robots alive when it was put.
    pub alive: Vec<String>,
    /// The robots that acknowledged it, in the order they did.
    pub acknowledged: Vec<Ack>,
    /// The robots alive that did not within the timeout.
    pub missing: Vec<String>,
    /// Whether the leader acknowledged it (its reference pauses during a
    /// stop; `false` also when there is no leader).
    pub leader: bool,
    /// The robots (of `missing`) that refused the resume, and why
    /// (`robot/1 refused resume 7 by operator: no valid operator token`).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub refused: Vec<String>,
}

/// The robots of `alive` that acknowledge `c` in `answers` (latch key,
/// payload), and whether the leader does.
pub fn tally(
    keys: &Keys,
    c: &FleetCommand,
    answers: &[(String, Vec<u8>)],
) -> (BTreeSet<String>, bool) {
    let mut robots = BTreeSet::new();
    let mut leader = false;
    for (key, payload) in answers {
        let Some(holder) = keys.latch_holder(key) else {
            continue;
        };
        if !Latched::decode(payload).is_some_and(|l| l.acknowledges(c)) {
            continue;
        }
        if holder == Member::Leader.liveliness() {
            leader = true;
        } else if holder.starts_with(&format!("{}/", Role::Robot)) {
            robots.insert(holder.to_owned());
        }
    }
    (robots, leader)
}

/// The robots whose latch answers in `answers` name stopping hazards their
/// base still reports, as one line (`robot/2 reports BUMP; robot/3 reports
/// EMERGENCY_STOP`), or `None`.
pub fn hazards_in_force(keys: &Keys, answers: &[(String, Vec<u8>)]) -> Option<String> {
    let reports: BTreeSet<String> = answers
        .iter()
        .filter_map(|(key, payload)| {
            let holder = keys.latch_holder(key)?;
            let l = Latched::decode(payload)?;
            (!l.hazards.is_empty()).then(|| format!("{holder} reports {}", l.hazards.names()))
        })
        .collect();
    (!reports.is_empty()).then(|| reports.into_iter().collect::<Vec<_>>().join("; "))
}

/// The robots whose latch answers in `answers` say they refused `c` (a
/// resume without a valid proof of their operator token), each with one
/// line: `robot/1 refused resume 7 by operator: no valid operator token`.
pub fn refusals(
    keys: &Keys,
    c: &FleetCommand,
    answers: &[(String, Vec<u8>)],
) -> BTreeMap<String, String> {
    let robot = format!("{}/", Role::Robot);
    answers
        .iter()
        .filter_map(|(key, payload)| {
            let holder = keys.latch_holder(key)?;
            let l = Latched::decode(payload)?;
            let acknowledged = l.acknowledges(c);
            let r = l.refused.filter(|r| r.is_of(c) && !acknowledged)?;
            holder
                .starts_with(&robot)
                .then(|| (holder.to_owned(), format!("{holder} refused {r}")))
        })
        .collect()
}

/// The highest command number in `answers` (0: none).
pub fn highest_seq(answers: &[(String, Vec<u8>)]) -> u64 {
    answers
        .iter()
        .filter_map(|(_, p)| Latched::decode(p))
        .map(|l| l.seq())
        .max()
        .unwrap_or(0)
}

/// The robots alive in the fleet of `keys` (their liveliness names).
fn alive_robots(session: &zenoh::Session, keys: &Keys) -> Result<Vec<String>, FleetError> {
    let prefix = keys.alive("");
    let replies = session
        .liveliness()
        .get(keys.alive(&format!("{}/*", Role::Robot)))
        .timeout(ASK)
        .wait()
        .map_err(|e| FleetError::Zenoh(format!("liveliness: {e}")))?;
    let mut alive = BTreeSet::new();
    while let Ok(reply) = replies.recv() {
        if let Ok(s) = reply.result()
            && let Some(name) = s.key_expr().as_str().strip_prefix(&prefix)
        {
            alive.insert(name.to_owned());
        }
    }
    Ok(alive.into_iter().collect())
}

/// Puts the command and waits for the acknowledgements (or `stop`).
pub fn run(opts: &OperatorOptions, stop: &StopFlag) -> Result<OperatorReport, FleetError> {
    if opts.order == Order::Resume && opts.token.is_none() {
        return Err(FleetError::Refused(NEEDS_TOKEN.to_owned()));
    }
    let keys = Keys::new(&opts.fleet);
    let session = net::open(&opts.net)?;
    let alive = alive_robots(&session, &keys)?;
    let before = runtime::query_all(&session, &keys.latches(), ASK)?;
    if opts.order == Order::Resume
        && let Some(why) = hazards_in_force(&keys, &before)
    {
        let _ = session.close().wait();
        return Err(FleetError::Refused(format!(
            "fleet resume refused: {why}; the fleet stays stopped until the base clears it"
        )));
    }
    let identity = opts
        .net
        .secure
        .as_ref()
        .map_or_else(|| Member::Operator.identity(), |s| s.identity.clone());
    let command = FleetCommand::new(
        opts.order,
        highest_seq(&before) + 1,
        &identity,
        &opts.reason,
    );
    let command = match (&opts.token, opts.order) {
        (Some(t), Order::Resume) => command.signed(t),
        _ => command,
    };
    net::put_stamped(&session, &keys.command(), command.encode());
    let published_unix_ns = crate::unix_nanos();
    let put = Instant::now();
    let mut acknowledged: Vec<Ack> = Vec::new();
    let mut leader = false;
    let mut seen: BTreeMap<String, f64> = BTreeMap::new();
    let mut refused: BTreeMap<String, String> = BTreeMap::new();
    loop {
        let answers = runtime::query_all(&session, &keys.latches(), ASK)?;
        let after = put.elapsed().as_secs_f64();
        let (robots, by_leader) = tally(&keys, &command, &answers);
        leader |= by_leader;
        for r in robots {
            seen.entry(r.clone()).or_insert_with(|| {
                acknowledged.push(Ack {
                    robot: r.clone(),
                    after,
                });
                after
            });
        }
        for (r, why) in refusals(&keys, &command, &answers) {
            if !seen.contains_key(&r) {
                refused.insert(r, why);
            }
        }
        refused.retain(|r, _| !seen.contains_key(r));
        // Every robot answered: it obeyed, or it refused (and will not
        // change its mind: waiting on is pointless).
        let done = alive
            .iter()
            .all(|r| seen.contains_key(r) || refused.contains_key(r));
        if (done && (leader || put.elapsed() > LEADER_GRACE)) || stop.is_raised() {
            break;
        }
        if put.elapsed() > opts.timeout {
            break;
        }
        std::thread::sleep(POLL);
    }
    let missing = alive
        .iter()
        .filter(|r| !seen.contains_key(*r))
        .cloned()
        .collect();
    let _ = session.close().wait();
    Ok(OperatorReport {
        role: Role::Operator,
        command,
        published_unix_ns,
        alive,
        acknowledged,
        missing,
        leader,
        refused: refused.into_values().collect(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::command::Latch;

    #[test]
    fn acknowledgements_are_the_latches_that_obey() {
        let keys = Keys::new("lab");
        let stop = FleetCommand::new(Order::Stop, 3, "operator", "");
        let mut obeying = Latch::new();
        obeying.on_command(stop.clone());
        let mut older = Latch::new();
        older.on_command(FleetCommand::new(Order::Stop, 2, "operator", ""));
        let answers = vec![
            (keys.latch("robot/1"), obeying.latched().encode()),
            (keys.latch("robot/2"), older.latched().encode()),
            (keys.latch("robot/3"), Latch::new().latched().encode()),
            (keys.latch("robot/4"), b"garbage".to_vec()),
            (keys.latch("leader"), obeying.latched().encode()),
            (
                Keys::new("other").latch("robot/5"),
                obeying.latched().encode(),
            ),
        ];
        let (robots, leader) = tally(&keys, &stop, &answers);
        assert_eq!(robots.into_iter().collect::<Vec<_>>(), vec!["robot/1"]);
        assert!(leader);
        assert_eq!(highest_seq(&answers), 3);
        assert_eq!(highest_seq(&[]), 0);
        let resume = FleetCommand::new(Order::Resume, 4, "operator", "");
        assert!(tally(&keys, &resume, &answers).0.is_empty());
    }

    /// The robots that refused a resume are those whose latch answer names
    /// that very resume (not an earlier one of the same number).
    #[test]
    fn refusals_name_the_robots_that_refused_this_resume() {
        let keys = Keys::new("lab");
        let token = OperatorToken::random().unwrap_or_else(|e| panic!("{e}"));
        let stop = FleetCommand::new(Order::Stop, 3, "operator", "");
        let resume = FleetCommand::new(Order::Resume, 4, "operator", "").signed(&token);
        let earlier = FleetCommand {
            stamp_unix_ns: resume.stamp_unix_ns.wrapping_sub(1),
            ..resume.clone()
        };
        let latch = |token: Option<OperatorToken>, heard: &[&FleetCommand]| {
            let mut l = Latch::with_token(token);
            l.on_command(stop.clone());
            for c in heard {
                l.on_command((*c).clone());
            }
            l.latched().encode()
        };
        let other = OperatorToken::random().unwrap_or_else(|e| panic!("{e}"));
        let answers = vec![
            (keys.latch("robot/1"), latch(None, &[&resume])),
            (keys.latch("robot/2"), latch(Some(other), &[&resume])),
            (
                keys.latch("robot/3"),
                latch(Some(token.clone()), &[&resume]),
            ),
            (keys.latch("robot/4"), latch(None, &[&earlier])),
            (keys.latch("leader"), latch(None, &[&resume])),
        ];
        let refused = refusals(&keys, &resume, &answers);
        assert_eq!(
            refused.values().cloned().collect::<Vec<_>>(),
            [
                "robot/1 refused resume 4 by operator: this process has no operator token",
                "robot/2 refused resume 4 by operator: no valid operator token",
            ]
        );
        let (acks, _) = tally(&keys, &resume, &answers);
        assert_eq!(acks.into_iter().collect::<Vec<_>>(), ["robot/3"]);
    }

    /// Without the token a resume is refused before anything is opened or
    /// put.
    #[test]
    fn a_resume_without_the_token_is_refused_before_anything_is_put() {
        let opts = OperatorOptions {
            fleet: "lab".into(),
            order: Order::Resume,
            reason: String::new(),
            timeout: Duration::from_millis(1),
            net: NetOptions::default(),
            token: None,
        };
        match run(&opts, &StopFlag::new()) {
            Err(FleetError::Refused(why)) => assert_eq!(why, NEEDS_TOKEN),
            other => panic!("{other:?}"),
        }
    }
}
