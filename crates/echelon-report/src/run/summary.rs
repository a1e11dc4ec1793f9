//! `summary.json`: read back as the type `echelon` writes it from
//! ([`RunSummary`], with its per-agent [`AgentSummary`], [`SafetyReport`]
//! and [`Divergence`]): one type for the fact, written and read.

pub use echelon::output::RunSummary;
pub use echelon::stats::{AgentSafety, AgentSummary, Divergence, SafetyReport};
