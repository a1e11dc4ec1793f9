//! Who is there before a task's clock starts: its latch answered and asked
//! ([`declare_latch`], [`ask_latches`], [`query_all`]), and the liveliness
//! tokens it waits for ([`wait_for`]).

use std::collections::BTreeSet;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use zenoh::Wait;
use zenoh::sample::SampleKind;

use crate::{FleetError, StopFlag};

use super::{LATCH_QUERY_TIMEOUT, Latching, WaitFor};

/// Declares the queryable answering on `key` with what `answer` holds.
pub(super) fn declare_latch(
    session: &zenoh::Session,
    key: &str,
    answer: Arc<Mutex<Option<Vec<u8>>>>,
) -> Result<zenoh::query::Queryable<()>, FleetError> {
    let reply_key = key.to_owned();
    session
        .declare_queryable(key)
        .callback(move |q| {
            let payload = answer.lock().ok().and_then(|a| a.clone());
            if let Some(p) = payload {
                let _ = q.reply(reply_key.clone(), p).wait();
            }
        })
        .wait()
        .map_err(|e| FleetError::Zenoh(format!("declaring the latch {key}: {e}")))
}

/// Asks every latch of `l.ask` (at most [`LATCH_QUERY_TIMEOUT`]): the
/// answers but the asker's own, `(key, payload)`.
pub(super) fn ask_latches(
    session: &zenoh::Session,
    l: &Latching,
) -> Result<Vec<(String, Vec<u8>)>, FleetError> {
    let mut heard = query_all(session, &l.ask, LATCH_QUERY_TIMEOUT)?;
    heard.retain(|(key, _)| !l.answer_on.contains(key));
    Ok(heard)
}

/// Every queryable's answers to a query on `ask` within `timeout`, `(key,
/// payload)`, unconsolidated.
pub fn query_all(
    session: &zenoh::Session,
    ask: &str,
    timeout: Duration,
) -> Result<Vec<(String, Vec<u8>)>, FleetError> {
    let replies = session
        .get(ask)
        .target(zenoh::query::QueryTarget::All)
        .consolidation(zenoh::query::ConsolidationMode::None)
        .timeout(timeout)
        .wait()
        .map_err(|e| FleetError::Zenoh(format!("asking {ask}: {e}")))?;
    let mut heard = Vec::new();
    while let Ok(reply) = replies.recv() {
        if let Ok(s) = reply.result() {
            heard.push((
                s.key_expr().as_str().to_owned(),
                s.payload().to_bytes().into_owned(),
            ));
        }
    }
    Ok(heard)
}

/// The liveliness tokens matching a key expression as they come and go
/// (those already there included, a subscription with its history), by
/// full key: which are present now, and which were ever seen.
pub struct Tokens {
    sets: Arc<Mutex<TokenSets>>,
    _sub: zenoh::pubsub::Subscriber<()>,
}

#[derive(Debug, Default)]
struct TokenSets {
    present: BTreeSet<String>,
    seen: BTreeSet<String>,
}

impl std::fmt::Debug for Tokens {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Tokens")
            .field("sets", &self.sets)
            .finish_non_exhaustive()
    }
}

impl Tokens {
    /// Watches the tokens of `key_expr` on `session` while it lives.
    pub fn watch(session: &zenoh::Session, key_expr: &str) -> Result<Tokens, FleetError> {
        let sets: Arc<Mutex<TokenSets>> = Arc::default();
        let sink = sets.clone();
        let _sub = session
            .liveliness()
            .declare_subscriber(key_expr)
            .history(true)
            .callback(move |s| {
                if let Ok(mut sets) = sink.lock() {
                    let key = s.key_expr().as_str().to_owned();
                    match s.kind() {
                        SampleKind::Put => {
                            sets.seen.insert(key.clone());
                            sets.present.insert(key);
                        }
                        SampleKind::Delete => {
                            sets.present.remove(&key);
                        }
                    }
                }
            })
            .wait()
            .map_err(|e| FleetError::Zenoh(format!("liveliness: {e}")))?;
        Ok(Tokens { sets, _sub })
    }

    fn read<T>(&self, f: impl FnOnce(&TokenSets) -> T) -> Result<T, FleetError> {
        self.sets
            .lock()
            .map(|s| f(&s))
            .map_err(|_| FleetError::Config("poisoned".into()))
    }

    /// The keys whose tokens are there now.
    pub fn present(&self) -> Result<BTreeSet<String>, FleetError> {
        self.read(|s| s.present.clone())
    }

    /// The keys whose tokens were ever there.
    pub fn seen(&self) -> Result<BTreeSet<String>, FleetError> {
        self.read(|s| s.seen.clone())
    }
}

/// Waits until every name of `w` has a liveliness token under
/// `echelon/<fleet>/alive/`, or its timeout passes (or `stop` is raised).
pub(super) fn wait_for(
    session: &zenoh::Session,
    w: &WaitFor,
    stop: &StopFlag,
) -> Result<(), FleetError> {
    if w.names.is_empty() {
        return Ok(());
    }
    let tokens = Tokens::watch(session, &w.keys.alive("**"))?;
    let started = Instant::now();
    loop {
        let seen = tokens.seen()?;
        let missing: Vec<String> = w
            .names
            .iter()
            .filter(|r| !seen.contains(&w.keys.alive(r)))
            .cloned()
            .collect();
        if missing.is_empty() {
            // Let the declarations that came with the tokens settle.
            std::thread::sleep(Duration::from_millis(100));
            return Ok(());
        }
        if stop.is_raised() {
            return Ok(());
        }
        if started.elapsed() > w.timeout {
            return Err(FleetError::Config(format!(
                "waited {:.0} s for {} to join the fleet",
                w.timeout.as_secs_f64(),
                missing.join(", ")
            )));
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// How long the tokens already held take to arrive after a liveliness
/// subscription is declared (its history), real time.
const HISTORY_SETTLE: Duration = Duration::from_millis(500);

/// Refuses ([`FleetError::Refused`]) when another process holds one of
/// `tokens` (liveliness keys `echelon/<fleet>/alive/<name>`) and keeps it for
/// `wait`: a member the fleet has only one of is already running. Who holds
/// what is learnt twice over: a liveliness subscription with its history
/// (kept up to date as tokens come and go) and a liveliness query per
/// look; a token either one saw is held.
pub(super) fn refuse_if_held(
    session: &zenoh::Session,
    tokens: &[String],
    wait: Duration,
    stop: &StopFlag,
) -> Result<(), FleetError> {
    let watched = tokens
        .iter()
        .map(|key| Tokens::watch(session, key))
        .collect::<Result<Vec<_>, _>>()?;
    let started = Instant::now();
    let mut said = false;
    loop {
        let mut held = BTreeSet::new();
        for w in &watched {
            held.extend(w.present()?);
        }
        for key in tokens {
            let replies = session
                .liveliness()
                .get(key)
                .timeout(Duration::from_secs(1))
                .wait()
                .map_err(|e| FleetError::Zenoh(format!("liveliness: {e}")))?;
            while let Ok(r) = replies.recv() {
                if let Ok(s) = r.result() {
                    held.insert(s.key_expr().as_str().to_owned());
                }
            }
        }
        if stop.is_raised() {
            return Ok(());
        }
        if held.is_empty() {
            if started.elapsed() >= HISTORY_SETTLE {
                return Ok(());
            }
            std::thread::sleep(Duration::from_millis(50));
            continue;
        }
        let names: Vec<String> = held
            .iter()
            .map(|k| {
                let mut parts = k.splitn(4, '/');
                let (_, fleet, _, name) = (parts.next(), parts.next(), parts.next(), parts.next());
                format!("{} of fleet `{}`", name.unwrap_or(k), fleet.unwrap_or("?"))
            })
            .collect();
        if started.elapsed() >= wait {
            return Err(FleetError::Refused(format!(
                "{} is already running (another process holds its liveliness token): a second one would drive it twice; stop the other first (a second `fleet up` of the same fleet, or the same robot started twice?)",
                names.join(", ")
            )));
        }
        if !said {
            eprintln!(
                "{} is already in the fleet: waiting up to {:.0} s for it to leave",
                names.join(", "),
                wait.as_secs_f64()
            );
            said = true;
        }
        std::thread::sleep(Duration::from_millis(200));
    }
}
