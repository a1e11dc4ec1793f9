//! The dashboard's **Stop all** and **Resume**: the fleet's `operator`
//! member, as `fleet stop` / `fleet resume` are ([`crate::operator`]), on a
//! Zenoh session of its own in the collector's process.
//!
//! An order goes out as `fleet stop` puts one: the robots' latches are asked
//! for the highest command number they answer ([`operator::highest_seq`]),
//! the command is numbered one past it (and past any this page sent), so a
//! resume lifts every stop issued before it, wherever it came from (a `fleet
//! stop` / `fleet resume` from the command line included), and put on
//! `echelon/<fleet>/command`; then the latches are asked every
//! [`operator::POLL`] until every robot that answered acknowledges it (or
//! refused it: a resume without a valid operator token), or [`ACK_WAIT`]
//! passes. A resume is signed with the fleet's operator token
//! ([`crate::token`]), the dashboard's own.
//!
//! In secure mode the session has the `operator` identity of the
//! collector's certificate directory (`fleet certs` makes it): the only
//! identity, with the leader's, whose commands the fleet's access control
//! accepts. Without that certificate the buttons are refused ([`Refused`]),
//! with the reason shown on the page.

use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use serde::Serialize;
use zenoh::Wait;

use crate::command::{FleetCommand, Order};
use crate::keys::Keys;
use crate::net::{self, NetOptions, Secure, identity_files};
use crate::operator::{self, POLL, tally};
use crate::role::{Member, Role};
use crate::runtime;
use crate::token::OperatorToken;

/// Longest wait for the latches' answers before an order is numbered.
pub(super) const ASK: Duration = Duration::from_millis(250);
/// Longest wait for the acknowledgements once an order is put.
pub(super) const ACK_WAIT: Duration = Duration::from_secs(1);
/// The `reason` of the commands the buttons give.
pub(super) const REASON: &str = "dashboard button";

/// Why the buttons are not offered.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(super) struct Refused(
    /// Why, in words for the page.
    pub(super) String,
);

/// What an order did (the page shows it; the HTTP answer's JSON).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub(super) struct Outcome {
    /// The command put.
    pub(super) command: FleetCommand,
    /// The robots whose latches answered before it was put.
    pub(super) robots: Vec<String>,
    /// Those that acknowledged it within [`ACK_WAIT`].
    pub(super) acknowledged: Vec<String>,
    /// Those that refused it, and why (`robot/1 refused resume 7 by
    /// operator: this process has no operator token`).
    pub(super) refused: Vec<String>,
}

/// The session, once open.
#[derive(Debug)]
enum Link {
    Opening,
    Open(zenoh::Session),
    Failed(String),
}

/// The operator behind the buttons.
#[derive(Debug)]
pub(super) struct Operator {
    keys: Keys,
    identity: String,
    link: Arc<Mutex<Link>>,
    /// The highest command number this page put.
    last: u64,
    /// Signs its resumes.
    token: OperatorToken,
}

/// The session options of the operator beside a collector joined with
/// `net`: the collector's mode, its endpoints to connect to and those it
/// listens on with a fixed port (a mesh reaches the fleet through it), no
/// listener of its own; in secure mode the `operator` identity of the same
/// certificate directory, or [`Refused`] if it is not there.
pub(super) fn operator_net(net: &NetOptions) -> Result<NetOptions, Refused> {
    let secure = match &net.secure {
        None => None,
        Some(s) => {
            let identity = Member::Operator.identity();
            let (cert, key) = identity_files(&s.dir, &identity);
            if let Some(missing) = [&cert, &key].into_iter().find(|f| !f.is_file()) {
                return Err(Refused(format!(
                    "Stop all is not offered: in secure mode the dashboard stops the fleet as `{identity}`, and {} is missing (make it with `echelon fleet certs {}`, or stop with `echelon fleet stop --secure DIR --identity {identity}`)",
                    missing.display(),
                    s.dir.display()
                )));
            }
            Some(Secure {
                identity,
                ..s.clone()
            })
        }
    };
    let fixed_port = |e: &&String| e.rsplit(':').next().is_some_and(|p| p != "0");
    let mut connect = net.connect.clone();
    connect.extend(net.listen.iter().filter(fixed_port).cloned());
    Ok(NetOptions {
        mode: net.mode,
        listen: Vec::new(),
        connect,
        zenoh_config: net.zenoh_config.clone(),
        secure,
    })
}

/// Opens a session with `opts`, without the listeners a configuration file
/// may name (the collector has them).
fn open(opts: &NetOptions) -> Result<zenoh::Session, String> {
    let mut config = net::config(opts).map_err(|e| e.to_string())?;
    if opts.zenoh_config.is_some() {
        config
            .insert_json5("listen/endpoints", "[]")
            .map_err(|e| e.to_string())?;
    }
    zenoh::open(config).wait().map_err(|e| e.to_string())
}

impl Operator {
    /// The operator of fleet `fleet` beside a collector joined with `net`:
    /// its session opens in the background (orders before then are refused
    /// as not yet connected); [`Refused`] in secure mode without the
    /// `operator` identity. Its resumes are signed with `token`.
    pub(super) fn start(
        fleet: &str,
        net: &NetOptions,
        token: OperatorToken,
    ) -> Result<Operator, Refused> {
        let opts = operator_net(net)?;
        let identity = opts
            .secure
            .as_ref()
            .map_or_else(|| Member::Operator.identity(), |s| s.identity.clone());
        let link = Arc::new(Mutex::new(Link::Opening));
        let opened = link.clone();
        let spawned = std::thread::Builder::new()
            .name("dashboard-operator".into())
            .spawn(move || {
                let l = match open(&opts) {
                    Ok(s) => Link::Open(s),
                    Err(e) => Link::Failed(e),
                };
                if let Ok(mut slot) = opened.lock() {
                    *slot = l;
                }
            });
        if let Err(e) = spawned {
            return Err(Refused(format!("Stop all is not offered: no thread: {e}")));
        }
        Ok(Operator {
            keys: Keys::new(fleet),
            identity,
            link,
            last: 0,
            token,
        })
    }

    /// Its identity (`operator`).
    pub(super) fn identity(&self) -> &str {
        &self.identity
    }

    fn session(&self) -> Result<zenoh::Session, String> {
        let link = self.link.lock().map_err(|_| "poisoned".to_owned())?;
        match &*link {
            Link::Open(s) => Ok(s.clone()),
            Link::Opening => Err("not connected to the fleet yet; try again".to_owned()),
            Link::Failed(e) => Err(format!("no session with the fleet: {e}")),
        }
    }

    /// Puts `order` as `fleet stop` / `fleet resume` does (the module doc)
    /// and waits for the acknowledgements; `Err`: why it could not.
    pub(super) fn order(&mut self, order: Order) -> Result<Outcome, String> {
        let session = self.session()?;
        let before =
            runtime::query_all(&session, &self.keys.latches(), ASK).map_err(|e| e.to_string())?;
        let seq = operator::highest_seq(&before).max(self.last) + 1;
        let command = FleetCommand::new(order, seq, &self.identity, REASON);
        let command = match order {
            Order::Resume => command.signed(&self.token),
            Order::Stop => command,
        };
        net::put_stamped(&session, &self.keys.command(), command.encode());
        self.last = seq;
        let put = Instant::now();
        let robot = format!("{}/", Role::Robot);
        let mut robots: Vec<String> = before
            .iter()
            .filter_map(|(key, _)| self.keys.latch_holder(key))
            .filter(|h| h.starts_with(&robot))
            .map(str::to_owned)
            .collect();
        robots.sort();
        robots.dedup();
        let (acknowledged, refused) = loop {
            let answers = runtime::query_all(&session, &self.keys.latches(), ASK)
                .map_err(|e| e.to_string())?;
            let acks: Vec<String> = tally(&self.keys, &command, &answers)
                .0
                .into_iter()
                .collect();
            let refused = operator::refusals(&self.keys, &command, &answers);
            let answered = |r: &String| acks.contains(r) || refused.contains_key(r);
            if robots.iter().all(answered) || put.elapsed() > ACK_WAIT {
                break (acks, refused.into_values().collect());
            }
            std::thread::sleep(POLL);
        };
        Ok(Outcome {
            command,
            robots,
            acknowledged,
            refused,
        })
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use super::*;

    #[test]
    fn the_operator_joins_where_the_collector_does() {
        let net = NetOptions {
            listen: vec!["tcp/127.0.0.1:7000".into(), "tcp/127.0.0.1:0".into()],
            connect: vec!["tcp/127.0.0.1:7001".into()],
            ..NetOptions::default()
        };
        let o = operator_net(&net).unwrap();
        assert!(o.listen.is_empty());
        assert_eq!(o.connect, ["tcp/127.0.0.1:7001", "tcp/127.0.0.1:7000"]);
        assert_eq!(o.secure, None);
    }

    /// In secure mode: the `operator` identity of the collector's
    /// directory, or a refusal naming the missing file and how to make it.
    #[test]
    fn in_secure_mode_the_operator_needs_its_certificate() {
        let dir = tempfile::tempdir().unwrap();
        let secure = |dir: &std::path::Path| NetOptions {
            secure: Some(Secure {
                dir: dir.to_path_buf(),
                identity: Member::Collector.identity(),
                robots: 2,
                ros2: Vec::new(),
            }),
            ..NetOptions::default()
        };
        let Refused(why) = operator_net(&secure(dir.path())).unwrap_err();
        assert!(
            why.contains("operator.pem") && why.contains("fleet certs"),
            "{why}"
        );
        let (cert, key) = identity_files(dir.path(), "operator");
        std::fs::write(&cert, "x").unwrap();
        assert!(operator_net(&secure(dir.path())).is_err(), "the key too");
        std::fs::write(&key, "x").unwrap();
        let o = operator_net(&secure(dir.path())).unwrap();
        let s = o.secure.unwrap();
        assert_eq!((s.identity.as_str(), s.robots), ("operator", 2));
    }
}
