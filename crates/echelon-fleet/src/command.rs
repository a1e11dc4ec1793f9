//! The fleet-wide command: `echelon fleet stop` / `fleet resume` (and the
//! leader's stop when it is interrupted), put on `echelon/<fleet>/command`
//! and obeyed by every robot.
//!
//! A command is a small JSON message ([`FleetCommand`]: the order, a
//! sequence number, who sent it, when and why). Every process that hears
//! commands (robots, the leader) keeps a [`Latch`]: the stop in force, if
//! any. The rules:
//!
//! - a **stop** is always obeyed, whatever its number (a stop is never
//!   unsafe); the latch keeps the highest stop number heard;
//! - a **resume** is obeyed only when it carries a valid proof of the
//!   operator token ([`crate::token`]) and the process holds that token
//!   ([`Latch::with_token`]), in every mode; any other resume is refused,
//!   counted (`unauthorized`) and named in the latch answer
//!   ([`Latched::refused`]), and changes nothing;
//! - an obeyed resume lifts the stop in force only when its number is
//!   higher than that stop's (`fleet resume` numbers its command one past
//!   the highest number the fleet answers, so it lifts every stop issued
//!   before it, and a resume that crossed a newer stop on the way does not);
//! - what a process learns second-hand (a latch answer, [`Latch::on_hearsay`])
//!   can only stop it: in secure mode only the `operator` and the `leader`
//!   may put on the command key, while any member may answer a query.
//!
//! The latch is held by the processes themselves (the robots and the
//! leader), each answering queries on its own `echelon/<fleet>/latch/<name>`
//! key with what is in force ([`Latched`]); a process that starts asks
//! `echelon/<fleet>/latch/**` before its clock starts, so a robot that
//! starts or restarts during a stop is stopped before its first tick. The
//! same answers are the acknowledgements `fleet stop` waits for.

use serde::{Deserialize, Serialize};

use crate::ros2::hazard::HazardSet;
use crate::token::{OperatorToken, PROOF_HEX_LEN};

/// What the signed bytes of a command start with (so that a proof is of a
/// fleet command, and of this layout, nothing else).
const SIGNED_DOMAIN: &[u8] = b"echelon.FleetCommand.proof.v1\0";

/// The longest command payload accepted, bytes.
pub const MAX_LEN: usize = 2048;
/// The longest `reason`, characters.
pub const MAX_REASON: usize = 256;
/// The longest `by`, characters.
const MAX_BY: usize = 64;
/// The format version written and accepted.
pub const COMMAND_VERSION: u32 = 1;

/// What a command orders.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(rename_all = "lowercase")]
pub enum Order {
    /// Command zero on every tick until resumed.
    Stop,
    /// Follow again, from where the robot is.
    Resume,
}

impl Order {
    /// Its name (`stop`, `resume`).
    pub fn name(self) -> &'static str {
        match self {
            Order::Stop => "stop",
            Order::Resume => "resume",
        }
    }
}

/// A fleet-wide command, as JSON on `echelon/<fleet>/command`.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
#[schemars(title = "echelon.FleetCommand")]
pub struct FleetCommand {
    /// [`COMMAND_VERSION`].
    pub version: u32,
    /// Stop or resume.
    pub order: Order,
    /// Its number: a resume lifts only the stops numbered below it.
    pub seq: u64,
    /// When its sender issued it, UNIX ns (the sender's wall clock; for the
    /// logs, not for ordering).
    pub stamp_unix_ns: u64,
    /// Who sent it: its sender's identity (`operator`, `leader`).
    pub by: String,
    /// Why, in a few words (may be empty).
    pub reason: String,
    /// The proof of the operator token ([`OperatorToken::sign`] of
    /// [`FleetCommand::signed_bytes`]), lowercase hexadecimal: a resume is
    /// obeyed only with a valid one, a stop needs none. Empty, and left out
    /// of the JSON, when the command is not signed.
    #[serde(default, skip_serializing_if = "String::is_empty")]
    pub proof: String,
}

/// Why a command payload was refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum CommandError {
    /// Too long, not JSON, or not a command.
    #[error("malformed command: {0}")]
    Malformed(&'static str),
    /// Another format version.
    #[error("command format version {0}, expected {COMMAND_VERSION}")]
    WrongVersion(u32),
}

impl FleetCommand {
    /// A command `order` numbered `seq`, sent now by `by` for `reason`.
    pub fn new(order: Order, seq: u64, by: &str, reason: &str) -> FleetCommand {
        FleetCommand {
            version: COMMAND_VERSION,
            order,
            seq,
            stamp_unix_ns: crate::unix_nanos(),
            by: by.chars().take(MAX_BY).collect(),
            reason: reason.chars().take(MAX_REASON).collect(),
            proof: String::new(),
        }
    }

    /// The same command signed with `token` (its [`FleetCommand::proof`]
    /// set: the token's proof of [`FleetCommand::signed_bytes`]).
    pub fn signed(self, token: &OperatorToken) -> FleetCommand {
        FleetCommand {
            proof: token.sign(&self.signed_bytes()),
            ..self
        }
    }

    /// Whether it carries a proof made with `token` (compared in constant
    /// time).
    pub fn verified_by(&self, token: &OperatorToken) -> bool {
        token.verify(&self.signed_bytes(), &self.proof)
    }

    /// The bytes a proof signs: `SIGNED_DOMAIN`, then the command's version
    /// (4 bytes), order name, sequence number (8 bytes), stamp (8 bytes),
    /// sender and reason, integers big-endian, each text preceded by its
    /// length in bytes (4 bytes big-endian), so that no two commands share
    /// them (everything but the proof).
    pub fn signed_bytes(&self) -> Vec<u8> {
        let text = |out: &mut Vec<u8>, s: &str| {
            out.extend_from_slice(&(s.len() as u32).to_be_bytes());
            out.extend_from_slice(s.as_bytes());
        };
        let mut out =
            Vec::with_capacity(SIGNED_DOMAIN.len() + 40 + self.by.len() + self.reason.len());
        out.extend_from_slice(SIGNED_DOMAIN);
        out.extend_from_slice(&self.version.to_be_bytes());
        text(&mut out, self.order.name());
        out.extend_from_slice(&self.seq.to_be_bytes());
        out.extend_from_slice(&self.stamp_unix_ns.to_be_bytes());
        text(&mut out, &self.by);
        text(&mut out, &self.reason);
        out
    }

    /// Its JSON.
    pub fn encode(&self) -> Vec<u8> {
        serde_json::to_vec(self).unwrap_or_default()
    }

    /// A command from its JSON, checked: at most [`MAX_LEN`] bytes, this
    /// version, a sender named, a reason of at most [`MAX_REASON`]
    /// characters.
    pub fn decode(bytes: &[u8]) -> Result<FleetCommand, CommandError> {
        if bytes.len() > MAX_LEN {
            return Err(CommandError::Malformed("too long"));
        }
        let v: serde_json::Value =
            serde_json::from_slice(bytes).map_err(|_| CommandError::Malformed("not JSON"))?;
        match v.get("version").and_then(serde_json::Value::as_u64) {
            Some(n) if n == u64::from(COMMAND_VERSION) => {}
            Some(n) => return Err(CommandError::WrongVersion(n.min(u64::from(u32::MAX)) as u32)),
            None => return Err(CommandError::Malformed("no version")),
        }
        let c: FleetCommand =
            serde_json::from_value(v).map_err(|_| CommandError::Malformed("not a command"))?;
        c.check()?;
        Ok(c)
    }

    /// The rules of a decoded command beyond its JSON shape: a sender
    /// named in at most `MAX_BY` characters, a reason of at most
    /// [`MAX_REASON`], a proof of at most [`PROOF_HEX_LEN`] lowercase
    /// hexadecimal characters; one place for the command key and the latch
    /// answers.
    fn check(&self) -> Result<(), CommandError> {
        if self.by.is_empty() || self.by.chars().count() > MAX_BY {
            return Err(CommandError::Malformed("sender"));
        }
        if self.reason.chars().count() > MAX_REASON {
            return Err(CommandError::Malformed("reason too long"));
        }
        if self.proof.len() > PROOF_HEX_LEN
            || !self
                .proof
                .bytes()
                .all(|b| b.is_ascii_digit() || (b'a'..=b'f').contains(&b))
        {
            return Err(CommandError::Malformed("proof"));
        }
        Ok(())
    }
}

/// A resume a latch refused: it carried no valid proof of the operator
/// token, or the process has no token ([`Latch::last_refusal`]).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Refusal {
    /// The resume's number.
    pub seq: u64,
    /// The resume's stamp (with `seq` and `by`, which resume it was).
    pub stamp_unix_ns: u64,
    /// The resume's sender.
    pub by: String,
    /// Why it was refused.
    pub why: String,
}

/// Why a latch refuses a resume without a valid proof.
pub const NO_VALID_PROOF: &str = "no valid operator token";
/// Why a latch without a token refuses every resume.
pub const NO_TOKEN_HERE: &str = "this process has no operator token";

impl Refusal {
    /// Whether it is the refusal of `c`.
    pub fn is_of(&self, c: &FleetCommand) -> bool {
        c.order == Order::Resume
            && self.seq == c.seq
            && self.stamp_unix_ns == c.stamp_unix_ns
            && self.by == c.by
    }
}

impl std::fmt::Display for Refusal {
    /// `resume 7 by operator: no valid operator token`.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "resume {} by {}: {}", self.seq, self.by, self.why)
    }
}

/// What a process answers on its latch key: whether it is stopped, the
/// command in force (the stop, or the last resume; `None`: none heard),
/// from a robot the stopping hazards its base reports (a fleet paused for
/// them may not be resumed: `fleet resume` refuses, naming them), and the
/// last resume it refused for want of a valid operator token.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Latched {
    /// Whether a stop is in force.
    pub stopped: bool,
    /// The command in force.
    pub command: Option<FleetCommand>,
    /// The stopping hazards its base reports (only while stopped).
    #[serde(default, skip_serializing_if = "HazardSet::is_empty")]
    pub hazards: HazardSet,
    /// The last resume it refused (no valid operator token), since the
    /// last one it obeyed.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub refused: Option<Refusal>,
}

impl Latched {
    /// Its JSON.
    pub fn encode(&self) -> Vec<u8> {
        serde_json::to_vec(self).unwrap_or_default()
    }

    /// From its JSON (`None`: not a latch answer).
    pub fn decode(bytes: &[u8]) -> Option<Latched> {
        if bytes.len() > 2 * MAX_LEN {
            return None;
        }
        let l: Latched = serde_json::from_slice(bytes).ok()?;
        let consistent = match &l.command {
            Some(c) => {
                (c.order == Order::Stop) == l.stopped
                    && c.version == COMMAND_VERSION
                    && c.check().is_ok()
            }
            None => !l.stopped,
        } && (l.hazards.is_empty() || l.stopped)
            && l.refused.as_ref().is_none_or(|r| {
                !r.by.is_empty()
                    && r.by.chars().count() <= MAX_BY
                    && r.why.chars().count() <= MAX_REASON
            });
        consistent.then_some(l)
    }

    /// The highest command number it knows.
    pub fn seq(&self) -> u64 {
        self.command.as_ref().map_or(0, |c| c.seq)
    }

    /// Whether it acknowledges `c`: the same order, numbered `c.seq` or
    /// later.
    pub fn acknowledges(&self, c: &FleetCommand) -> bool {
        self.command
            .as_ref()
            .is_some_and(|l| l.order == c.order && l.seq >= c.seq)
    }
}

/// What the commands a process received did (its report's `commands`).
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, schemars::JsonSchema,
)]
#[serde(deny_unknown_fields)]
pub struct CommandCounts {
    /// Command payloads received on the command key.
    pub received: u64,
    /// Times it went from running to stopped (on a command or a latch answer).
    pub stops: u64,
    /// Times a resume set it running again.
    pub resumes: u64,
    /// Payloads refused: malformed or of another version.
    pub refused: u64,
    /// Resumes ignored: not stopped, or numbered at or below the stop in
    /// force.
    pub ignored: u64,
    /// Resumes refused because the robot's base still reported a stopping
    /// hazard (it stopped the fleet again).
    #[serde(default)]
    pub refused_resumes: u64,
    /// Resumes refused for want of a valid operator token proof (or
    /// because the process has no token).
    #[serde(default)]
    pub unauthorized: u64,
}

/// What a command did to a latch.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Change {
    /// It was running and is stopped now.
    Stopped,
    /// It was stopped and runs again.
    Resumed,
    /// Nothing changed (a stop while stopped, a resume ignored or
    /// refused; [`Latch::last_refusal`]).
    Unchanged,
}

/// A line for a process's log about a command it just took (`change`; its
/// latch answer now, its counts `before` and `after`): the resume obeyed
/// (its number, sender and reason), or the resume refused (the first ten
/// refusals, then every power of two: a flood of resumes does not flood
/// the log). `None`: nothing to say.
pub fn resume_note(
    change: Change,
    now: &Latched,
    before: CommandCounts,
    after: CommandCounts,
) -> Option<String> {
    if change == Change::Resumed {
        let r = now.command.as_ref().filter(|c| c.order == Order::Resume)?;
        return Some(format!(
            "fleet resume {} by {} obeyed (reason: {:?})",
            r.seq, r.by, r.reason
        ));
    }
    let n = after.unauthorized;
    if n > before.unauthorized && (n <= 10 || n.is_power_of_two()) {
        let r = now.refused.as_ref()?;
        return Some(format!("fleet {r}: refused ({n} refused so far)"));
    }
    None
}

/// The fleet command a process is under (see the module's rules).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Latch {
    /// The stop in force (the highest-numbered one heard).
    stop: Option<FleetCommand>,
    /// The last resume obeyed.
    resume: Option<FleetCommand>,
    counts: CommandCounts,
    /// Moves whenever what [`Latch::latched`] answers changes.
    changes: u64,
    /// The operator token a resume must prove (none: every resume is
    /// refused).
    token: Option<OperatorToken>,
    /// The last resume refused for want of a valid proof, since the last
    /// one obeyed.
    refusal: Option<Refusal>,
}

impl Latch {
    /// Running, nothing heard, no operator token: it obeys stops and
    /// refuses every resume.
    pub fn new() -> Latch {
        Latch::default()
    }

    /// Running, nothing heard, obeying the resumes signed with `token`
    /// (none: refusing every resume).
    pub fn with_token(token: Option<OperatorToken>) -> Latch {
        Latch {
            token,
            ..Latch::default()
        }
    }

    /// Whether it holds an operator token (else it refuses every resume).
    pub fn has_token(&self) -> bool {
        self.token.is_some()
    }

    /// The last resume it refused for want of a valid operator token
    /// proof, since the last one it obeyed (its `Display`: `resume 7 by
    /// operator: no valid operator token`).
    pub fn last_refusal(&self) -> Option<&Refusal> {
        self.refusal.as_ref()
    }

    /// Whether a stop is in force.
    pub fn stopped(&self) -> bool {
        self.stop.is_some()
    }

    /// The stop in force.
    pub fn stop(&self) -> Option<&FleetCommand> {
        self.stop.as_ref()
    }

    /// Its counters.
    pub fn counts(&self) -> CommandCounts {
        self.counts
    }

    /// A number that moves whenever what [`Latch::latched`] answers
    /// changes (and only then may it differ): a holder of the encoded
    /// answer re-encodes it only when this moved.
    pub fn changes(&self) -> u64 {
        self.changes
    }

    /// What it answers on its latch key.
    pub fn latched(&self) -> Latched {
        Latched {
            stopped: self.stopped(),
            command: self.stop.clone().or_else(|| self.resume.clone()),
            hazards: HazardSet::EMPTY,
            refused: self.refusal.clone(),
        }
    }

    /// Counts a resume its holder refused after the latch obeyed it (its
    /// base reports a hazard; the holder stops again at once).
    pub fn refuse_resume(&mut self) {
        self.counts.refused_resumes += 1;
    }

    /// The highest command number it knows.
    pub fn seq(&self) -> u64 {
        self.stop
            .iter()
            .chain(&self.resume)
            .map(|c| c.seq)
            .max()
            .unwrap_or(0)
    }

    /// Takes a payload that arrived on the command key: decoded (refused and
    /// counted if malformed) and obeyed by the rules.
    pub fn on_payload(&mut self, bytes: &[u8]) -> Change {
        self.counts.received += 1;
        match FleetCommand::decode(bytes) {
            Ok(c) => self.on_command(c),
            Err(_) => {
                self.counts.refused += 1;
                Change::Unchanged
            }
        }
    }

    /// Obeys `c`: a stop always; a resume with a valid proof of its
    /// operator token ([`OperatorToken::verify`]) numbered above the stop
    /// in force. A resume without a valid proof, or any resume when it has
    /// no token, is refused: counted (`unauthorized`), kept as
    /// [`Latch::last_refusal`], nothing else changed.
    pub fn on_command(&mut self, c: FleetCommand) -> Change {
        match c.order {
            Order::Stop => self.take_stop(c),
            Order::Resume => {
                let why = match &self.token {
                    None => Some(NO_TOKEN_HERE),
                    Some(t) if !c.verified_by(t) => Some(NO_VALID_PROOF),
                    Some(_) => None,
                };
                if let Some(why) = why {
                    return self.refuse(&c, why);
                }
                match &self.stop {
                    Some(s) if c.seq > s.seq => {
                        self.stop = None;
                        self.resume = Some(c);
                        self.refusal = None;
                        self.changes += 1;
                        self.counts.resumes += 1;
                        Change::Resumed
                    }
                    _ => {
                        self.counts.ignored += 1;
                        if self.stop.is_none() && self.resume.as_ref().is_none_or(|r| c.seq > r.seq)
                        {
                            // Running anyway: keep the newest number.
                            self.resume = Some(c);
                            self.refusal = None;
                            self.changes += 1;
                        }
                        Change::Unchanged
                    }
                }
            }
        }
    }

    /// A line for its holder's log about a resume it just took
    /// ([`resume_note`]).
    pub fn resume_note(&self, change: Change, before: CommandCounts) -> Option<String> {
        resume_note(change, &self.latched(), before, self.counts)
    }

    /// Refuses resume `c` for `why`: counted and kept, nothing else changed.
    fn refuse(&mut self, c: &FleetCommand, why: &str) -> Change {
        self.counts.unauthorized += 1;
        let refusal = Refusal {
            seq: c.seq,
            stamp_unix_ns: c.stamp_unix_ns,
            by: c.by.clone(),
            why: why.to_owned(),
        };
        if self.refusal.as_ref() != Some(&refusal) {
            self.refusal = Some(refusal);
            self.changes += 1;
        }
        Change::Unchanged
    }

    /// Takes robot `k`'s own stop, put on its halt key
    /// ([`crate::keys::Keys::halt`]): a stop sent by robot `k` is obeyed as
    /// any stop; anything else there (a resume, another sender, garbage) is
    /// refused and counted.
    pub fn on_halt(&mut self, k: u32, bytes: &[u8]) -> Change {
        self.counts.received += 1;
        match FleetCommand::decode(bytes) {
            Ok(c) if c.order == Order::Stop && c.by == crate::role::Member::Robot(k).identity() => {
                self.take_stop(c)
            }
            _ => {
                self.counts.refused += 1;
                Change::Unchanged
            }
        }
    }

    /// Takes another process's latch answer (hearsay): only a stop is taken.
    pub fn on_hearsay(&mut self, bytes: &[u8]) -> Change {
        match Latched::decode(bytes) {
            Some(Latched {
                stopped: true,
                command: Some(c),
                ..
            }) => self.take_stop(c),
            _ => Change::Unchanged,
        }
    }

    fn take_stop(&mut self, c: FleetCommand) -> Change {
        let change = if self.stop.is_none() {
            self.counts.stops += 1;
            Change::Stopped
        } else {
            Change::Unchanged
        };
        if self.stop.as_ref().is_none_or(|s| c.seq >= s.seq) && self.stop.as_ref() != Some(&c) {
            self.stop = Some(c);
            self.changes += 1;
        }
        change
    }
}

#[cfg(test)]
mod tests;
