//! What the filter keeps a robot apart from: its neighbours ([`Neighbour`]),
//! static obstacles ([`Obstacle`]), the point `L` ahead that is kept apart
//! ([`point`]), and the check that robots start outside each other's radius
//! ([`start_conflict`]).

use super::config::SafetyConfig;
use crate::check;
use crate::error::ParamError;
use crate::model::State;

/// A static disc obstacle, built through [`Obstacle::new`] (which checks it).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Obstacle {
    pub(super) x: f64,
    pub(super) y: f64,
    pub(super) r: f64,
}

impl Obstacle {
    /// Refuses a centre that is not finite and `r` that is not `> 0`.
    pub fn new(x: f64, y: f64, r: f64) -> Result<Obstacle, ParamError> {
        check::finite("x", x)?;
        check::finite("y", y)?;
        check::positive("r", r)?;
        Ok(Obstacle { x, y, r })
    }

    /// Centre, m.
    #[inline]
    pub const fn x(&self) -> f64 {
        self.x
    }

    /// Centre, m.
    #[inline]
    pub const fn y(&self) -> f64 {
        self.y
    }

    /// Radius, m (`> 0`).
    #[inline]
    pub const fn r(&self) -> f64 {
        self.r
    }
}

/// What a robot knows of a neighbour: its point `L` ahead and that point's
/// motion (from the neighbour's state stream in a fleet, from the state in the
/// simulator).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Neighbour {
    /// `p_j`, m.
    pub p: [f64; 2],
    /// `ṗ_j`, m/s (used only for a non-cooperative neighbour, and for `ḣ` of
    /// the torque constraint).
    pub dp: [f64; 2],
    /// `p̈_j`, m/s² (only for a non-cooperative neighbour of a torque-driven
    /// robot; zero when unknown).
    pub ddp: [f64; 2],
    /// Whether the neighbour is a torque-driven robot running this filter
    /// whose `ddp` is its point's acceleration under the command its filter
    /// answered last ([`Neighbour::sharing`]): a torque robot then also
    /// takes what the neighbour fell short of its half of their barrier
    /// (`docs/safety.md`, "Torque robots in a crowd").
    pub shares: bool,
    /// Whether the neighbour runs this filter too and so takes half of each
    /// pair constraint.
    pub cooperative: bool,
    /// Extra clearance for this pair beyond the radius, m: the position
    /// uncertainty of the two robots' estimates (`docs/safety.md`,
    /// "Uncertain positions"; 0 when both are known exactly).
    pub margin: f64,
}

impl Neighbour {
    /// The neighbour seen from its state `s` and its `L`: `p_j`, and `ṗ_j` from
    /// its velocities `(v, ω)`; `dv = (v̇, ω̇)` gives `p̈_j` (`None`: zero).
    pub fn of_state(s: &State, l: f64, dv: Option<[f64; 2]>, cooperative: bool) -> Neighbour {
        let (sin, cos) = s.theta.sin_cos();
        let dp = [s.v * cos - l * s.omega * sin, s.v * sin + l * s.omega * cos];
        let ddp = dv.map_or([0.0; 2], |[a, alpha]| {
            let along = a - l * s.omega * s.omega;
            let across = s.v * s.omega + l * alpha;
            [along * cos - across * sin, along * sin + across * cos]
        });
        Neighbour {
            p: point(s, l),
            dp,
            ddp,
            shares: false,
            cooperative,
            margin: 0.0,
        }
    }

    /// The same neighbour, when `shares`, a torque-driven robot running
    /// this filter, its `dv` given to [`Neighbour::of_state`] the
    /// acceleration under the command its filter answered last
    /// ([`super::SafetyFilter::last_acceleration`]): a torque robot's filter then
    /// takes over what that neighbour fell short of its half of their
    /// barrier (squeezed between two, it could not take it). Safe whatever
    /// the measurement: the extra is never negative.
    pub fn sharing(self, shares: bool) -> Neighbour {
        Neighbour { shares, ..self }
    }

    /// The same neighbour with the pair's radius widened by `margin` m.
    pub fn with_margin(self, margin: f64) -> Neighbour {
        Neighbour { margin, ..self }
    }
}

/// How many standard deviations of each robot's position estimate widen a
/// pair's radius ([`uncertainty_margin`]).
pub const UNCERTAINTY_SIGMAS: f64 = 3.0;

/// The extra clearance a pair of robots keeps between their *estimated*
/// points when the estimates are uncertain: `3 (σ_i + σ_j)`, with `σ` the
/// standard deviation of each estimate along its most uncertain axis. If
/// each robot's true point is within `3σ` of its estimate (per axis, 99.7 %
/// for a Gaussian error), estimates `radius + 3(σ_i + σ_j)` apart put the
/// true points at least `radius` apart: drift cannot make two robots
/// collide while their filters believe them clear.
pub fn uncertainty_margin(sigma_me: f64, sigma_other: f64) -> f64 {
    UNCERTAINTY_SIGMAS * (sigma_me.max(0.0) + sigma_other.max(0.0))
}

/// `p = (x, y) + L (cos θ, sin θ)`: the point the filter keeps apart.
#[inline]
pub fn point(s: &State, l: f64) -> [f64; 2] {
    let (sin, cos) = s.theta.sin_cos();
    [s.x + l * cos, s.y + l * sin]
}

/// The first robot (index) whose point `L` ahead starts inside the safe
/// set's complement, and why: within `radius` of another robot's point
/// (`points[i]`, the larger radius of the two robots that filter) or of an
/// obstacle's edge. `configs[i]` is `None` for a robot that does not filter
/// (it is checked only against robots that do).
pub fn start_conflict(
    points: &[[f64; 2]],
    configs: &[Option<SafetyConfig>],
    obstacles: &[Obstacle],
) -> Option<(usize, ParamError)> {
    let radius = |i: usize| configs.get(i).copied().flatten().map(|c| c.radius);
    for (i, p) in points.iter().enumerate() {
        for (j, q) in points.iter().enumerate().take(i) {
            let r = match (radius(i), radius(j)) {
                (None, None) => continue,
                (a, b) => a.unwrap_or(0.0).max(b.unwrap_or(0.0)),
            };
            let d = (p[0] - q[0]).hypot(p[1] - q[1]);
            if d < r {
                return Some((
                    i,
                    ParamError::new(
                        "start",
                        d,
                        format!(
                            "m from agent {}'s point L ahead: closer than the safety radius {r} m",
                            j + 1
                        ),
                    ),
                ));
            }
        }
        let Some(r) = radius(i) else { continue };
        for (k, o) in obstacles.iter().enumerate() {
            let clear = (p[0] - o.x).hypot(p[1] - o.y) - o.r;
            if clear < r {
                return Some((
                    i,
                    ParamError::new(
                        "start",
                        clear,
                        format!(
                            "m from obstacle {}'s edge (its point L ahead): closer than the safety radius {r} m",
                            k + 1
                        ),
                    ),
                ));
            }
        }
    }
    None
}
