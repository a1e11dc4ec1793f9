//! Typed errors. Every message says what is wrong and why it is refused.

use std::borrow::Cow;

/// `v` for a message: plain, or in exponent form when very large or small
/// (`1e30`, not thirty-one digits).
pub fn num(v: f64) -> String {
    let a = v.abs();
    if a != 0.0 && !(1e-3..1e5).contains(&a) {
        format!("{v:e}")
    } else {
        format!("{v}")
    }
}

/// A physical or control parameter with an impossible value.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{field} = {value}: {reason}")]
pub struct ParamError {
    /// The parameter's field name, as in the scenario file.
    pub field: &'static str,
    /// The refused value.
    pub value: f64,
    /// Why it is refused (`must be a finite number > 0`).
    pub reason: Cow<'static, str>,
}

impl ParamError {
    /// A new error for `field = value`.
    pub fn new(field: &'static str, value: f64, reason: impl Into<Cow<'static, str>>) -> Self {
        ParamError {
            field,
            value,
            reason: reason.into(),
        }
    }
}

/// A reference trajectory that cannot be built.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ReferenceError {
    /// A parameter out of its domain.
    #[error(transparent)]
    Param(#[from] ParamError),
    /// Fewer than two waypoints.
    #[error("a waypoint path needs at least 2 points, got {0}")]
    TooFewWaypoints(usize),
    /// Waypoint times not strictly increasing.
    #[error(
        "waypoint {index} (1-based) has time {} s, not after the previous one ({} s)",
        num(*.t),
        num(*.previous)
    )]
    TimesNotIncreasing {
        /// 1-based index of the offending waypoint.
        index: usize,
        /// Its time.
        t: f64,
        /// The previous waypoint's time.
        previous: f64,
    },
    /// A waypoint coordinate that is not a finite number.
    #[error("waypoint {index} (1-based): its {} = {value} is not a finite number", ["t", "x", "y"][*.coordinate % 3])]
    NonFiniteWaypoint {
        /// 1-based index of the offending waypoint.
        index: usize,
        /// Which coordinate: 0 for `t`, 1 for `x`, 2 for `y`.
        coordinate: usize,
        /// Its value.
        value: f64,
    },
    /// Two consecutive waypoints closer in time than `min_gap`
    /// (`Waypoints::MIN_GAP`): the spline between them would swing through
    /// absurd speeds.
    #[error(
        "waypoint {index} (1-based) at t = {} s is only {} s after waypoint {} at t = {} s: consecutive waypoints must be at least {} s apart",
        num(*.t),
        num(.t - .previous),
        .index - 1,
        num(*.previous),
        num(*.min_gap)
    )]
    WaypointsTooClose {
        /// 1-based index of the later waypoint.
        index: usize,
        /// Its time, s.
        t: f64,
        /// The previous waypoint's time, s.
        previous: f64,
        /// The shortest gap allowed, s.
        min_gap: f64,
    },
    /// Two consecutive waypoints whose distance over their time gap is an
    /// average speed above `max_speed` (`Waypoints::MAX_SPEED`).
    #[error(
        "waypoints {} and {index} (1-based; t = {} s and t = {} s) are {} m apart: an average speed of {} m/s, above the {} m/s a reference may have",
        .index - 1,
        num(*.previous),
        num(*.t),
        num(*.distance),
        num(*.speed),
        .max_speed
    )]
    WaypointsTooFast {
        /// 1-based index of the later waypoint.
        index: usize,
        /// Its time, s.
        t: f64,
        /// The previous waypoint's time, s.
        previous: f64,
        /// Distance between the two, m.
        distance: f64,
        /// `distance / (t − previous)`, m/s.
        speed: f64,
        /// The largest average speed allowed, m/s.
        max_speed: f64,
    },
    /// The spline through waypoints within the speed limit on average that
    /// still exceeds `max_speed` (`Waypoints::MAX_SPEED`) between two of
    /// them (times unevenly spaced make it overshoot).
    #[error(
        "between waypoints {} and {index} (1-based; t = {} s and t = {} s) the path through the waypoints reaches {} m/s (at t = {} s), above the {} m/s a reference may have: space the waypoints more evenly in time",
        .index - 1,
        num(*.previous),
        num(*.t),
        num(*.speed),
        num(*.at),
        .max_speed
    )]
    WaypointsOvershoot {
        /// 1-based index of the later waypoint.
        index: usize,
        /// Its time, s.
        t: f64,
        /// The previous waypoint's time, s.
        previous: f64,
        /// When the speed is too high, s.
        at: f64,
        /// The speed there, m/s.
        speed: f64,
        /// The largest speed allowed, m/s.
        max_speed: f64,
    },
}

/// A leader graph that is not a forest rooted at the reference.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum FormationError {
    /// An agent follows an agent that does not exist.
    #[error("agent {agent} follows agent {leader}, which does not exist (agents are 1..={count})")]
    Dangling {
        /// The follower (1-based).
        agent: usize,
        /// The missing leader (1-based).
        leader: usize,
        /// Number of agents.
        count: usize,
    },
    /// An agent follows itself.
    #[error("agent {0} follows itself")]
    SelfLeader(usize),
    /// The leader graph has a cycle: nobody in it is anchored to the reference.
    #[error("agents {} form a cycle of leaders: none of them reaches the reference", fmt_cycle(.0))]
    Cycle(Vec<usize>),
    /// Exact `L̇_Y`, `L̈_Y` need the leader's 3rd and 4th derivatives, which only
    /// analytic references provide.
    #[error(
        "agent {agent} follows agent {leader}: exact L_Y derivatives need an analytic reference (use ly_derivatives = \"neglect\")"
    )]
    ExactDerivativesNeedReference {
        /// The follower (1-based).
        agent: usize,
        /// Its robot leader (1-based).
        leader: usize,
    },
    /// A torque-driven follower needs its leader's `v̇` (`p̈_d`, eq. 13), which a
    /// velocity base without a speed lag does not have (its speed jumps with
    /// the command).
    #[error(
        "agent {agent} is torque-driven and follows agent {leader}, a velocity base with tau_v = 0 whose acceleration is undefined (give the leader tau_v > 0 or the follower a velocity base)"
    )]
    NoLeaderAcceleration {
        /// The follower (1-based).
        agent: usize,
        /// Its robot leader (1-based).
        leader: usize,
    },
    /// A slot in the leader's frame turns with the leader's heading, which
    /// a reference standing still does not have.
    #[error(
        "agent {agent} holds its offset in the leader's frame (offset.frame = \"leader\") behind a reference that stands still at times (cubic, waypoints, or speed 0), where it has no heading; use a circle, line or lemniscate that keeps moving, or the follower's frame"
    )]
    LeaderFrameNeedsHeading {
        /// The follower (1-based).
        agent: usize,
    },
}

fn fmt_cycle(c: &[usize]) -> String {
    let mut s = String::new();
    for a in c.iter().chain(c.first()) {
        if !s.is_empty() {
            s.push_str(" → ");
        }
        s.push_str(&a.to_string());
    }
    s
}

/// Errors from building or running a simulation.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SimError {
    /// A parameter of the run or of one agent is impossible.
    #[error("{context}: {source}")]
    Param {
        /// Where: `sim`, `agent 3`, `agent 3 robot`, ...
        context: String,
        /// The parameter error.
        source: ParamError,
    },
    /// The formation graph is invalid.
    #[error(transparent)]
    Formation(#[from] FormationError),
    /// Timing parameters that do not fit together.
    #[error("{0}")]
    Timing(String),
    /// An agent's state stopped being finite or left its physical bounds
    /// ([`crate::sim::guard::Bounds`]): the run is stopped there.
    #[error("agent {agent} ({name}) diverged at t = {t} s: {breach}")]
    Diverged {
        /// The agent (1-based).
        agent: usize,
        /// Its name.
        name: String,
        /// Simulation time, s.
        t: f64,
        /// What left its bound.
        breach: Breach,
    },
    /// An observer failed (e.g. an I/O error while logging).
    #[error("observer: {0}")]
    Observer(String),
}

impl SimError {
    /// For `map_err`: a [`ParamError`] as a [`SimError::Param`] of `context`
    /// (`sim`, `base`, `agent 3 robot`, ...).
    pub fn param(context: &str) -> impl FnOnce(ParamError) -> SimError + use<> {
        let context = context.to_owned();
        move |source| SimError::Param { context, source }
    }
}

/// What left its bound ([`crate::sim::guard::Bounds::check`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Breach {
    /// The quantity: `x`, `y`, `theta`, `v`, `omega` (not finite), `|v|`,
    /// `|omega|`, `‖(x, y)‖`.
    pub quantity: &'static str,
    /// Its value.
    pub value: f64,
    /// Its bound (infinite for a value that is not finite).
    pub bound: f64,
    /// Its unit.
    pub unit: &'static str,
}

impl std::fmt::Display for Breach {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        if self.value.is_finite() {
            write!(
                f,
                "{} = {:.3e} {} left its bound {} {}",
                self.quantity, self.value, self.unit, self.bound, self.unit
            )
        } else {
            write!(f, "{} is {} (not finite)", self.quantity, self.value)
        }
    }
}
