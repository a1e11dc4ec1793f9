//! What a robot reports of its fixes: the counts, the intervals, the
//! odometry error measured and Theorem 2's requirement.

use serde::{Deserialize, Serialize};

use echelon::odometry::bound::KinematicTheorem2;

/// Theorem 2's `γ` (as `echelon bound`'s default).
pub const GAMMA: f64 = 0.99;

/// What a robot counted of its fixes.
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, schemars::JsonSchema,
)]
#[serde(deny_unknown_fields)]
pub struct FixCounters {
    /// Fix messages received.
    pub received: u64,
    /// Fused into the estimate.
    pub applied: u64,
    /// Refused by the gate (implausibly far from the estimate).
    pub gated: u64,
    /// Applied over the gate after [`RELOCALIZE_AFTER`](super::RELOCALIZE_AFTER) refusals in a row.
    pub relocalized: u64,
    /// Refused: another type or hash on the key.
    pub wrong_type: u64,
    /// Refused: not CDR of the message type, or no usable orientation (not
    /// a unit quaternion within tf2's tolerance).
    pub malformed: u64,
    /// Refused: a NaN or an infinity.
    pub non_finite: u64,
    /// Refused: another `frame_id` than configured.
    pub wrong_frame: u64,
    /// Refused: no odometry at the fix's stamp (older than the history, or
    /// no odometry yet).
    pub unmatched: u64,
    /// Refused: it would put the robot farther from the world origin than
    /// the divergence guard's position bound (`[sim] bounds`). Absent from
    /// the stats of earlier versions: 0.
    #[serde(default)]
    pub beyond_bounds: u64,
    /// Times fixes went missing for longer than the timeout.
    pub outages: u64,
}

/// Theorem 2 for this robot: the inputs (as `echelon bound --law kinematic`
/// takes them) and the fix interval they require.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct FixRequirement {
    /// `K_e`.
    pub ke: f64,
    /// `ζ`, m per odometry sample (the error model at the base's top speed).
    pub zeta: f64,
    /// `γ`.
    pub gamma: f64,
    /// The odometry sample period `T_s`, s.
    pub sample_period: f64,
    /// The formation tolerance `max ‖e‖`, m.
    pub tolerance: f64,
    /// The largest `N` keeping `‖e‖` within the tolerance.
    pub steps: u64,
    /// `N T_s`: the longest interval between fixes Theorem 2 allows, s.
    pub interval: f64,
}

impl FixRequirement {
    /// Theorem 2 (kinematic law) for gain `ke`, `zeta` m per sample of
    /// `sample_period` s and `tolerance` m; `None` when `ζ = 0` (perfect
    /// odometry needs no fix).
    pub fn new(
        ke: f64,
        zeta: f64,
        sample_period: f64,
        tolerance: f64,
    ) -> Result<Option<FixRequirement>, String> {
        if zeta == 0.0 {
            return Ok(None);
        }
        let t = KinematicTheorem2::new(ke, zeta, GAMMA).map_err(|e| e.to_string())?;
        let steps = t.max_steps(tolerance).map_err(|e| e.to_string())?;
        Ok(Some(FixRequirement {
            ke,
            zeta,
            gamma: GAMMA,
            sample_period,
            tolerance,
            steps,
            interval: steps as f64 * sample_period,
        }))
    }
}

/// What a robot reports of its fixes, live (its stats) and at the end.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct FixReport {
    /// The counts.
    pub counters: FixCounters,
    /// The longest interval between two applied fixes, s.
    pub interval_max: Option<f64>,
    /// The mean interval between applied fixes, s.
    pub interval_mean: Option<f64>,
    /// Time since the last applied fix (or since odometry began), s.
    pub age: Option<f64>,
    /// The largest position innovation per axis per odometry sample seen
    /// at a fix: the odometry error measured, m (Theorem 2's `ζ` as the
    /// robot actually drifted).
    pub zeta_measured: Option<f64>,
    /// Theorem 2's requirement (with a `tolerance`).
    pub required: Option<FixRequirement>,
    /// Whether an interval between fixes exceeded the requirement.
    pub too_slow: bool,
}
