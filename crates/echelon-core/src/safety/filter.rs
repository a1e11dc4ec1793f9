//! The filter itself: [`SafetyFilter`] (its settings, the QP's rows and the
//! deadlock monitor), its answer ([`Filtered`], [`Outcome`]) and the rows
//! common to velocity bases and torque-driven robots: the barriers, the speed
//! envelope ([`Envelope`]) and the emergency box ([`EMERGENCY_ACCEL`]).

use super::config::SafetyConfig;
use super::deadlock::{Deadlock, ENCOUNTER_SHARE};
use super::neighbour::{Neighbour, Obstacle};
use super::qp::{Constraint, solve};
use crate::model::{Input, State};

/// `p`, 1/s: the inner pole of the torque barrier, `ψ̇₁ + p ψ₁ ≥ 0` with
/// `ψ₁ = ḣ + γ h` (`p = max(γ, INNER_RATE)`). With both poles at `−γ` (the
/// filter before issue 20) `ψ₁` could fall no faster than `γ ψ₁`, and since
/// `ḧ` carries `2 dᵀp̈`, which grows with the distance `d`, a robot moving
/// away from a neighbour metres off was forbidden to brake (friction alone
/// decelerates Table I's robots at `η v/m ≈ 6 m/s²` at 1 m/s): the filter
/// kept it driving away, the law's braking refused. `ψ₁ ≥ 0` still keeps
/// `h ≥ 0`; the inner loop, on the robot's acceleration, is just allowed to
/// be faster than the outer one.
pub const INNER_RATE: f64 = 5.0;

/// What the filter did to a command.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Outcome {
    /// The (limited) nominal command satisfied every constraint: unchanged.
    #[default]
    Nominal,
    /// Replaced by the QP's answer.
    Filtered,
    /// The QP was infeasible or the solver failed: the least violation
    /// within the actuator limits, or a brake.
    Braked,
}

/// The filter's answer for one robot at one instant.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Filtered<C> {
    /// The command to send to the base.
    pub command: C,
    /// The law's command, as given.
    pub nominal: C,
    /// What the filter did.
    pub outcome: Outcome,
    /// Whether the robot is breaking a deadlock (its nominal was turned).
    pub deadlock: bool,
    /// Smallest distance from this robot's point to a neighbour's point
    /// within range, m (infinite: none).
    pub min_distance: f64,
}

impl<C> Filtered<C> {
    /// Whether the command differs from the nominal one.
    pub fn active(&self) -> bool {
        self.outcome != Outcome::Nominal
    }

    /// The answer for a robot whose state or nominal is not finite: the
    /// nominal passed through untouched (no QP on it), for the divergence
    /// guard to report.
    pub(super) fn passed(nominal: C) -> Filtered<C>
    where
        C: Copy,
    {
        Filtered {
            command: nominal,
            nominal,
            outcome: Outcome::Nominal,
            deadlock: false,
            min_distance: f64::INFINITY,
        }
    }

    /// The answer for what [`SafetyFilter::decide`] chose: the `limited`
    /// nominal when it passes, the QP's `x` as a command (`of`) when filtered,
    /// `braked()` when no command satisfies every row.
    pub(super) fn decided(
        (x, outcome, deadlock): ([f64; 2], Outcome, bool),
        nominal: C,
        limited: C,
        min_distance: f64,
        of: impl FnOnce([f64; 2]) -> C,
        braked: impl FnOnce() -> C,
    ) -> Filtered<C> {
        let command = match outcome {
            Outcome::Nominal => limited,
            Outcome::Braked => braked(),
            Outcome::Filtered => of(x),
        };
        Filtered {
            command,
            nominal,
            outcome,
            deadlock,
            min_distance,
        }
    }
}

/// One robot's safety filter: its settings, the QP's buffers and the deadlock
/// monitor. Call [`velocity`](SafetyFilter::velocity) or
/// [`torque`](SafetyFilter::torque) once per controller period with the
/// neighbours the robot knows of (any number; those beyond `range` are
/// ignored) and the known obstacles.
#[derive(Debug, Clone)]
pub struct SafetyFilter {
    pub(super) config: SafetyConfig,
    pub(super) rows: Vec<Constraint>,
    pub(super) deadlock: Deadlock,
    /// How long each command is held, s (0: continuous).
    pub(super) period: f64,
    /// The point's speed relative to the neighbour or obstacle whose
    /// barrier it is nearest, at the last call, m/s (infinite: none).
    pub(super) relative: f64,
    /// For each neighbour's barrier row of the last call (they come first,
    /// the obstacles' after), whether that neighbour's point comes toward
    /// this robot's head on ([`ONCOMING`]).
    pub(super) oncoming: Vec<bool>,
    /// The backward speed the base accepts this period, m/s (infinite: no
    /// limit; [`SafetyFilter::set_reverse_cap`]).
    pub(super) reverse: f64,
    /// The torques this filter answered last (zero before its first
    /// answer: a robot at rest with no command;
    /// [`SafetyFilter::last_acceleration`]).
    pub(super) last: Input,
}

/// Two points that move toward each other, each at least this fast (m/s)
/// along the line between them, meet *head on*: with a nominal that closes
/// on the neighbour faster than their barrier allows, the two are in an
/// encounter (the deadlock monitor's [`super::ENCOUNTER_SHARE`]). One that
/// moves along with the robot (a neighbour it rides beside,
/// `tests/safety_livelock.rs`) or only catches up with it (the one behind
/// in a column, while this robot brakes for one ahead) is not.
const ONCOMING: f64 = 0.01;

/// Where the deadlock monitor reads how fast the robot's point moves over
/// ground ([`SafetyFilter::decide`]).
#[derive(Debug, Clone, Copy)]
pub(super) enum Speed<'a> {
    /// From the robot's state and its point's distance ahead `L`, m.
    State(&'a State, f64),
    /// The filtered command in the QP's variables `x = (v, L ω)`: a
    /// lag-free velocity base's point moves at it.
    Command,
}

/// The robot's own geometry at one instant.
#[derive(Debug, Clone, Copy)]
pub(super) struct Own {
    p: [f64; 2],
    pub(super) dp: [f64; 2],
    pub(super) cos: f64,
    pub(super) sin: f64,
}

impl SafetyFilter {
    /// A filter with `config` (valid by [`SafetyConfig::new`]).
    pub fn new(config: SafetyConfig) -> SafetyFilter {
        SafetyFilter {
            config,
            rows: Vec::with_capacity(16),
            deadlock: Deadlock::default(),
            period: 0.0,
            relative: f64::INFINITY,
            oncoming: Vec::with_capacity(16),
            reverse: f64::INFINITY,
            last: Input { u1: 0.0, u2: 0.0 },
        }
    }

    /// The same filter for commands held `period` seconds (the controller's
    /// period): a velocity base's barrier rows then use the heading half a
    /// period ahead at the current turn rate. A command `(v, ω)` held for
    /// `T` from heading `θ` moves the point on average along
    /// `R(θ + ωT/2) (v, Lω) sinc(ωT/2)`, not `R(θ) (v, Lω)`; with a 10 ms
    /// period at 4 rad/s the difference let two points come 1–2 mm inside
    /// the radius (issue 20's survey).
    pub fn with_period(self, period: f64) -> SafetyFilter {
        SafetyFilter {
            period: if period.is_finite() && period > 0.0 {
                period
            } else {
                0.0
            },
            ..self
        }
    }

    /// Its settings.
    pub fn config(&self) -> &SafetyConfig {
        &self.config
    }

    /// The constraints given to the last QP (barriers, then limits), in the
    /// QP's variables.
    pub fn constraints(&self) -> &[Constraint] {
        &self.rows
    }

    /// Pushes one barrier row per neighbour in range and per obstacle, made
    /// by `row(d, h, neighbour)`; returns the smallest distance to a
    /// neighbour's point in range.
    pub(super) fn barriers(
        &mut self,
        own: &Own,
        neighbours: &[Neighbour],
        obstacles: &[Obstacle],
        row: impl Fn([f64; 2], f64, Option<&Neighbour>) -> Constraint,
    ) -> f64 {
        let SafetyConfig { radius, range, .. } = self.config;
        let mut min_distance = f64::INFINITY;
        self.oncoming.clear();
        // The nearest barrier (distance beyond it, m) and the point's speed
        // relative to its owner.
        let mut nearest = (f64::INFINITY, f64::INFINITY);
        let speed = |v: [f64; 2]| (own.dp[0] - v[0]).hypot(own.dp[1] - v[1]);
        for n in neighbours {
            let d = [own.p[0] - n.p[0], own.p[1] - n.p[1]];
            let dist = d[0].hypot(d[1]);
            if dist > range {
                continue;
            }
            min_distance = min_distance.min(dist);
            let r = radius + n.margin;
            let h = d[0] * d[0] + d[1] * d[1] - r * r;
            if dist - r < nearest.0 {
                nearest = (dist - r, speed(n.dp));
            }
            self.rows.push(row(d, h, Some(n)));
            // Head on: j's point comes toward this one's (d̂ᵀṗ_j) and this
            // one's goes toward j's (−d̂ᵀṗ_i). A neighbour that only comes
            // toward it (the one behind in a column, catching up while this
            // robot brakes for one ahead) is not an encounter.
            let toward = d[0] * n.dp[0] + d[1] * n.dp[1];
            let going = -(d[0] * own.dp[0] + d[1] * own.dp[1]);
            self.oncoming
                .push(toward >= ONCOMING * dist && going >= -ONCOMING * dist);
        }
        for o in obstacles {
            let d = [own.p[0] - o.x, own.p[1] - o.y];
            let clear = o.r + radius;
            let h = d[0] * d[0] + d[1] * d[1] - clear * clear;
            let beyond = d[0].hypot(d[1]) - clear;
            if beyond < nearest.0 {
                nearest = (beyond, speed([0.0; 2]));
            }
            self.rows.push(row(d, h, None));
        }
        self.relative = nearest.1;
        min_distance
    }
}

/// The smallest half-width, m/s², of the acceleration box in which a
/// torque-driven robot without wheel-torque limits takes its emergency
/// action (the box also holds the nominal and friction's brake); a velocity
/// base with lags and no limits takes it within the speeds its lags reach at
/// this acceleration ([`SafetyFilter::velocity`]).
pub const EMERGENCY_ACCEL: f64 = 20.0;

/// The speed envelope a torque-driven robot's filtered command keeps it in
/// (and a velocity base's with lags, [`SafetyFilter::velocity`]):
/// `−v_reverse ≤ v ≤ v_max`, `|ω| ≤ omega_max`, each as a first-order barrier
/// `ḣ ≥ −κ h` on `(u1, u2)` (`v̇ = (u1 − η v)/m`, `ω̇ = (u2 − ψ ω)/J`, eq. 3),
/// rows of the QP like the torque limit (a nominal command that satisfies
/// every barrier is not held to them).
///
/// Why (issue 20): the filter steers the point `L` ahead, whose acceleration
/// `(u1/m, L u2/J)` the QP changes as little as possible. The heading is that
/// output's internal (zero) dynamics: holding the point's lateral
/// acceleration needs `ω̇ ≈ −(v/L) ω`, unstable at rate `|v|/L` whenever
/// `v < 0` (20/s per m/s at `L = 0.05 m`), and a lateral correction of the
/// point costs the QP `L` times less than the angular acceleration it
/// demands. Unbounded, a filter that pushed a robot backwards made it spin
/// up (12 rad/s in 3 s) and the run diverge (‖e‖ ≈ 1e213 m). The envelope
/// bounds the state the filter may create, and with no reverse (the default)
/// the heading stays on the stable side of its zero dynamics: the filter may
/// slow a robot to a stop, never drive it backwards. When the envelope and
/// the barriers conflict the QP is infeasible and the robot brakes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Envelope {
    /// Largest forward speed, m/s.
    pub v_max: f64,
    /// Largest reverse speed, m/s (`v ≥ −v_reverse`).
    pub v_reverse: f64,
    /// Largest turn rate, rad/s.
    pub omega_max: f64,
    /// `κ`, 1/s: how fast the state is brought back inside.
    pub rate: f64,
}

impl Envelope {
    /// The default envelope: 1.5 m/s forward, no reverse, 4 rad/s, κ = 5/s.
    pub const DEFAULT: Envelope = Envelope {
        v_max: 1.5,
        v_reverse: 0.0,
        omega_max: 4.0,
        rate: 5.0,
    };

    /// The envelope of a velocity base with lags: its own speed limits (the
    /// default's where it has none), no reverse, the default's rate.
    pub(super) fn lagged(base: &crate::model::base::VelocityBase) -> Envelope {
        let finite = |x: f64, default: f64| if x.is_finite() { x } else { default };
        Envelope {
            v_max: finite(base.v_max(), Envelope::DEFAULT.v_max),
            omega_max: finite(base.omega_max(), Envelope::DEFAULT.omega_max),
            ..Envelope::DEFAULT
        }
    }

    /// The four rows in the QP's variables `x` at speeds `(v, w)`, for a
    /// robot whose speeds move as `v̇ = gain₁ x₁ − drag₁`,
    /// `ω̇ = gain₂ x₂ − drag₂` (torques, `x = (u1/m, L u2/J)`: gain `(1, 1/L)`,
    /// drag `(η v/m, ψ ω/J)`; a velocity base with lags, `x = (v*, L ω*)`:
    /// gain `(1/τ_v, 1/(L τ_ω))`, drag `(v/τ_v, ω/τ_ω)`).
    pub(super) fn push_rows(
        &self,
        rows: &mut Vec<Constraint>,
        gain: [f64; 2],
        [dv, dw]: [f64; 2],
        v: f64,
        w: f64,
    ) {
        let k = self.rate;
        // v_max − v ≥ 0:      −v̇ ≥ −κ (v_max − v)
        rows.push(Constraint {
            a: [-gain[0], 0.0],
            b: -k * (self.v_max - v) - dv,
        });
        // v + v_reverse ≥ 0:   v̇ ≥ −κ (v + v_reverse)
        rows.push(Constraint {
            a: [gain[0], 0.0],
            b: -k * (v + self.v_reverse) + dv,
        });
        // omega_max ∓ ω ≥ 0
        rows.push(Constraint {
            a: [0.0, -gain[1]],
            b: -k * (self.omega_max - w) - dw,
        });
        rows.push(Constraint {
            a: [0.0, gain[1]],
            b: -k * (self.omega_max + w) + dw,
        });
    }
}

impl SafetyFilter {
    /// Pushes the exponential barrier of relative degree two,
    /// `ḧ + (γ + p) ḣ + γ p h ≥ 0` (`p = max(γ, `[`INNER_RATE`]`)`), for every
    /// neighbour in range and every obstacle, for a robot whose point moves
    /// as `p̈ = f + R(θ) diag(scale) x` in the QP's variables `x` (torques:
    /// `scale = (1, 1)`; a velocity base with lags: `(1/τ_v, 1/τ_ω)`). A
    /// cooperative neighbour takes half of the pair; a non-cooperative
    /// one's measured `p̈_j` enters. A torque robot (`share`) whose
    /// neighbour is a torque robot running this filter too
    /// ([`Neighbour::sharing`]) also takes what that neighbour fell short
    /// of its own half at its acceleration now: robot i's row
    /// `2dᵀp̈_i ≥ −½D + max(0, −½D + 2dᵀp̈_j⁰)` with
    /// `D = 2‖Δṗ‖² + (γ+p)ḣ + γph`. The extra term is never negative, so the
    /// pair's rows still sum to at least the barrier whatever either robot
    /// measured of the other; and it is zero whenever the neighbour took its
    /// half, so a robot that pushes on its neighbour cannot drag it along.
    /// A robot squeezed between two neighbours that both close on it cannot
    /// take its half of both pairs (its QP is infeasible); the shortfall
    /// shows in its acceleration, and its partners take it over at their
    /// next call. Returns the smallest distance to a neighbour's point in
    /// range.
    pub(super) fn second_order_barriers(
        &mut self,
        own: &Own,
        neighbours: &[Neighbour],
        obstacles: &[Obstacle],
        f: [f64; 2],
        scale: [f64; 2],
        share: bool,
    ) -> f64 {
        let gamma = self.config.gain;
        self.barriers(own, neighbours, obstacles, |d, h, n| {
            let row = own.row(d);
            let a = [row[0] * scale[0], row[1] * scale[1]];
            let (dpj, ddpj) = n.map_or(([0.0; 2], [0.0; 2]), |n| (n.dp, n.ddp));
            let rel = [own.dp[0] - dpj[0], own.dp[1] - dpj[1]];
            let dh = 2.0 * (d[0] * rel[0] + d[1] * rel[1]);
            // Everything in ḧ + (γ + p) ḣ + γ p h that x does not move
            // (ψ₁ = ḣ + γ h, ψ̇₁ + p ψ₁ ≥ 0).
            let p = INNER_RATE.max(gamma);
            let drift =
                2.0 * (rel[0] * rel[0] + rel[1] * rel[1]) + (gamma + p) * dh + gamma * p * h;
            let df = 2.0 * (d[0] * f[0] + d[1] * f[1]);
            let b = match n {
                // A torque robot running this filter too: it takes its half,
                // and what its neighbour fell short of its own half at its
                // acceleration now (squeezed, it could not take it).
                Some(n) if n.cooperative && share && n.shares => {
                    let short = -0.5 * drift + 2.0 * (d[0] * n.ddp[0] + d[1] * n.ddp[1]);
                    -df - 0.5 * drift + short.max(0.0)
                }
                Some(n) if n.cooperative => -df - 0.5 * drift,
                _ => -df + 2.0 * (d[0] * ddpj[0] + d[1] * ddpj[1]) - drift,
            };
            Constraint { a, b }
        })
    }
}

impl Own {
    /// The geometry of `me`, its rows turned to the heading `ahead` seconds
    /// on at its turn rate (0: now).
    pub(super) fn ahead(me: &State, l: f64, ahead: f64) -> Own {
        let (sin, cos) = (me.theta + me.omega * ahead).sin_cos();
        let Neighbour { p, dp, .. } = Neighbour::of_state(me, l, None, true);
        Own { p, dp, cos, sin }
    }

    /// `2 dᵀ R(θ) x = a · x`: `a = 2 R(θ)ᵀ d` (the point moves at `R(θ) x`).
    pub(super) fn row(&self, d: [f64; 2]) -> [f64; 2] {
        [
            2.0 * (d[0] * self.cos + d[1] * self.sin),
            2.0 * (-d[0] * self.sin + d[1] * self.cos),
        ]
    }
}

impl SafetyFilter {
    /// Whether the filter holds the robot: it changed the command (and so
    /// may be stuck or breaking a deadlock) at its last call or at any call
    /// within [`super::DEADLOCK_MEMORY`] before it (a robot that keeps falling back
    /// into the same stand-off between breaks, or rides along a neighbour's
    /// barrier beside its slot, is held too).
    pub fn deadlocked(&self) -> bool {
        self.deadlock.held()
    }

    /// How many deadlocks it has started breaking.
    pub fn deadlock_breaks(&self) -> u64 {
        self.deadlock.breaks()
    }

    /// The law's tracking error ‖e‖ (m, eq. 7) at the coming call of
    /// [`velocity`](SafetyFilter::velocity) or [`torque`](SafetyFilter::torque):
    /// the deadlock monitor's progress measure. While the filter keeps
    /// acting, ‖e‖ must fall by [`super::PROGRESS_FRACTION`] within
    /// [`super::PROGRESS_WINDOW`], else the robot starts breaking a deadlock
    /// (or tries the next turn): a robot riding beside a neighbour that sits
    /// between it and its slot moves, so the motion test alone never calls
    /// it stuck. A filter never told (NaN) uses the motion test alone.
    pub fn set_tracking_error(&mut self, error: f64) {
        self.deadlock.set_error(error);
    }

    /// The backward speed `cap` (m/s, `≥ 0`; infinite: no limit) a velocity
    /// base accepts until told otherwise: a Create 3's backup budget
    /// ([`crate::model::base::Backup::cap`]). The filter then certifies only
    /// commands with `v ≥ −cap` (a hard row, and the nominal is held to it
    /// first), so that what it hands on is what the base carries out: a
    /// command cut after the filter (its reverse refused, its turn kept)
    /// would move the robot's point as no barrier allowed. NaN or negative:
    /// no reverse.
    pub fn set_reverse_cap(&mut self, cap: f64) {
        self.reverse = if cap >= 0.0 { cap } else { 0.0 };
    }

    /// The QP's answer for the desired `x0` and the rows gathered, the
    /// outcome and whether a deadlock is being broken; updates the monitor.
    /// `drift` is the part of the point's motion the command does not set
    /// (zero for velocity bases), for the stuck test; `speed` the point's
    /// speed over ground (m/s) for the still test and the progress test's
    /// ground motion: [`Speed::State`] from the robot's state (torques, a
    /// lagged base: the command moves it only through its dynamics), or
    /// [`Speed::Command`], the filtered point velocity itself (a lag-free
    /// base moves at its command; its state may carry only the command it
    /// was last asked for, as a caller that gives poses without speeds does).
    pub(super) fn decide(
        &mut self,
        t: f64,
        x0: [f64; 2],
        barriers: usize,
        drift: [f64; 2],
        speed: Speed<'_>,
    ) -> ([f64; 2], Outcome, bool) {
        let satisfied = |rows: &[Constraint], x: [f64; 2]| rows.iter().all(|c| c.slack(x) >= 0.0);
        if satisfied(&self.rows[..barriers], x0) {
            self.deadlock.free(t);
            return (x0, Outcome::Nominal, false);
        }
        // Stuck: less than half of the motion the nominal asks for survives
        // (the point stops, or slides alongside a neighbour it should pass);
        // in an encounter, less than ENCOUNTER_SHARE.
        let asked = [x0[0] + drift[0], x0[1] + drift[1]];
        let asked_sq = asked[0] * asked[0] + asked[1] * asked[1];
        let kept = |x: [f64; 2], share: f64| {
            let moved = [x[0] + drift[0], x[1] + drift[1]];
            asked_sq < 1e-4 || moved[0] * asked[0] + moved[1] * asked[1] >= share * asked_sq
        };
        // An encounter: the nominal closes on an oncoming neighbour
        // (`a·x₀ < 0`: its point moves toward the neighbour's, which comes
        // toward it) faster than that pair's row allows; then the robot
        // keeps right early ([`ENCOUNTER_SHARE`]).
        let encounter = self
            .rows
            .iter()
            .zip(&self.oncoming)
            .any(|(c, &on)| on && c.slack(x0) < 0.0 && c.a[0] * x0[0] + c.a[1] * x0[1] < 0.0);
        let share = if encounter { ENCOUNTER_SHARE } else { 0.5 };
        let (want, mut breaking) = self.deadlock.want(t, x0);
        // Breaking, but the nominal itself, unturned, would keep nearly all
        // of its motion (ENCOUNTER_SHARE): the robot is clear of what held
        // it (its nominal only asks more than a barrier allows, say a
        // torque robot's hard turn beside neighbours 0.6 m off), and the
        // break ends, or its turned desire carries it on round a circle
        // away from its goal (issue trust2, item 4). Not in an encounter
        // (keeping right is what gets it past), nor a break the progress
        // test started: a robot riding beside a neighbour in its way keeps
        // most of its nominal too, and that break is what moves it on.
        let clear = (breaking && !encounter && !self.deadlock.by_progress())
            .then(|| solve(&self.rows, x0))
            .flatten()
            .filter(|&x| kept(x, ENCOUNTER_SHARE));
        let (x, outcome) = match clear {
            Some(x) => {
                self.deadlock.end_break();
                breaking = false;
                (x, Outcome::Filtered)
            }
            None => match solve(&self.rows, want) {
                Some(x) => (x, Outcome::Filtered),
                None => ([0.0; 2], Outcome::Braked),
            },
        };
        let stuck = !kept(x, share);
        // Still: the point stands (below 1 mm/s) and the filtered motion is
        // next to nothing (1 %) of what is asked.
        let speed = match speed {
            Speed::State(me, l) => me.v.hypot(l * me.omega),
            Speed::Command => x[0].hypot(x[1]),
        };
        let moved = [x[0] + drift[0], x[1] + drift[1]];
        let still = speed < 1e-3 && moved[0] * moved[0] + moved[1] * moved[1] < 1e-4 * asked_sq;
        self.deadlock
            .record(t, stuck, still, encounter, [self.relative, speed]);
        (x, outcome, breaking)
    }
}
