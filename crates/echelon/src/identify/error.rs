//! What identification refuses, and why.

use super::Model;

/// Why a log cannot be identified. Every message names the log.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum IdentifyError {
    /// The log could not be read or parsed.
    #[error("{file}: {reason}")]
    Read {
        /// The log.
        file: String,
        /// What went wrong.
        reason: String,
    },
    /// Columns the model needs are absent.
    #[error("{file}: missing column(s) {columns} (the {model} model needs {needed})")]
    MissingColumns {
        /// The log.
        file: String,
        /// The absent columns, comma-separated.
        columns: String,
        /// The model asked for.
        model: Model,
        /// Every column it needs.
        needed: String,
    },
    /// The chosen agent has no rows.
    #[error("{file}: no rows for agent {agent} (agents in the log: {present})")]
    NoAgent {
        /// The log.
        file: String,
        /// The agent asked for.
        agent: usize,
        /// The agents present.
        present: String,
    },
    /// Too few samples.
    #[error("{file}: log too short: {samples} samples of agent {agent}, at least {min} needed")]
    TooShort {
        /// The log.
        file: String,
        /// The agent.
        agent: usize,
        /// Samples found.
        samples: usize,
        /// Samples needed ([`MIN_SAMPLES`](super::MIN_SAMPLES)).
        min: usize,
    },
    /// A needed value is NaN or infinite.
    #[error("{file}: non-finite {column} = {value} at t = {t} s (agent {agent})")]
    NonFinite {
        /// The log.
        file: String,
        /// The column.
        column: &'static str,
        /// The value.
        value: f64,
        /// Its time.
        t: f64,
        /// The agent.
        agent: usize,
    },
    /// Sample times do not increase.
    #[error("{file}: time does not increase at t = {t} s (agent {agent})")]
    Time {
        /// The log.
        file: String,
        /// The time that does not follow its predecessor.
        t: f64,
        /// The agent.
        agent: usize,
    },
    /// An MCAP log lacks the channels the model needs.
    #[error("{file}: missing {what} (topics in the file: {present})")]
    MissingTopics {
        /// The log.
        file: String,
        /// What is missing.
        what: String,
        /// The topics it has, comma-separated.
        present: String,
    },
    /// Neither axis was excited: nothing can be identified.
    #[error("{file}: no excitation: {reason}")]
    NoExcitation {
        /// The log.
        file: String,
        /// Why, per axis.
        reason: String,
    },
}
