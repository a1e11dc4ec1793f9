//! Reference trajectories `p_d(t)` with exact time derivatives.
//!
//! Derivatives come from closed forms (circle, line, cubic, spline) or from
//! automatic differentiation with dual numbers (lemniscate), never from finite
//! differences. The law needs `p_d, ṗ_d, p̈_d`; exact `L̇_Y, L̈_Y` also need
//! `p⃛_d` and `p⁗_d` (see [`crate::law::lycomp`]).

use std::fmt;
use std::sync::Arc;

use num_dual::{Dual2, DualNum};

use crate::check::{finite, require};
use crate::error::ReferenceError;
use crate::math::lanes::Lanes;
use crate::math::sinc;

mod spline;
use spline::{Septic, check_waypoints};

/// A planar position and its first four time derivatives.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Jet {
    /// Position `p`, m.
    pub p: [f64; 2],
    /// Velocity `ṗ`, m/s.
    pub dp: [f64; 2],
    /// Acceleration `p̈`, m/s².
    pub ddp: [f64; 2],
    /// Jerk `p⃛`, m/s³ (zero unless requested with [`Order::Four`]).
    pub d3p: [f64; 2],
    /// Snap `p⁗`, m/s⁴ (zero unless requested with [`Order::Four`]).
    pub d4p: [f64; 2],
}

/// Speeds below this are treated as standing still: the heading and the
/// curvature of the path are then undefined and taken as zero turn rate.
pub const STANDSTILL: f64 = 1e-12;

impl Jet {
    /// A jet from each axis' value and derivatives 1–4.
    #[inline]
    pub fn from_axes(x: [f64; 5], y: [f64; 5]) -> Jet {
        Jet {
            p: [x[0], y[0]],
            dp: [x[1], y[1]],
            ddp: [x[2], y[2]],
            d3p: [x[3], y[3]],
            d4p: [x[4], y[4]],
        }
    }

    /// Speed along the path, `V_d = ‖ṗ_d‖`.
    #[inline]
    pub fn speed(&self) -> f64 {
        self.dp[0].hypot(self.dp[1])
    }

    /// Turn rate `ω_d = (ẋ ÿ − ẏ ẍ) / V_d²` (zero when standing still).
    #[inline]
    pub fn turn_rate(&self) -> f64 {
        let v2 = self.dp[0] * self.dp[0] + self.dp[1] * self.dp[1];
        if v2 <= STANDSTILL * STANDSTILL {
            0.0
        } else {
            (self.dp[0] * self.ddp[1] - self.dp[1] * self.ddp[0]) / v2
        }
    }

    /// The path's heading `θ_d`, turn rate `ω_d` and angular acceleration
    /// `ω̇_d = (ẋ y⃛ − ẏ x⃛)/V_d² − 2 ω_d (ṗ·p̈)/V_d²` (`p⃛` is zero unless the
    /// jet was evaluated with [`Order::Four`]). Standing still, the heading
    /// is that of the first derivative that is not zero (`p̈`, then `p⃛`: the
    /// direction a path at rest leaves in), or zero, and both rates zero.
    pub fn frame(&self) -> (f64, f64, f64) {
        let [dx, dy] = self.dp;
        let v2 = dx * dx + dy * dy;
        if v2 <= STANDSTILL * STANDSTILL {
            return (rest_heading(&[self.ddp, self.d3p]), 0.0, 0.0);
        }
        let [ddx, ddy] = self.ddp;
        let [d3x, d3y] = self.d3p;
        let omega = (dx * ddy - dy * ddx) / v2;
        let domega = (dx * d3y - dy * d3x) / v2 - 2.0 * omega * (dx * ddx + dy * ddy) / v2;
        (dy.atan2(dx), omega, domega)
    }

    /// Heading of the velocity, `atan2(ẏ, ẋ)` (zero when standing still).
    pub fn heading(&self) -> f64 {
        if self.speed() <= STANDSTILL {
            0.0
        } else {
            self.dp[1].atan2(self.dp[0])
        }
    }
}

/// The heading of a point at rest: that of the first of `derivatives` that
/// is not zero, or zero.
pub fn rest_heading(derivatives: &[[f64; 2]]) -> f64 {
    derivatives
        .iter()
        .find(|d| d[0].hypot(d[1]) > STANDSTILL)
        .map_or(0.0, |d| d[1].atan2(d[0]))
}

/// How many derivatives a caller needs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum Order {
    /// `p, ṗ, p̈`: what the law needs.
    Two,
    /// Up to `p⁗`: what exact `L̇_Y, L̈_Y` need.
    Four,
}

/// A reference trajectory: anything that gives `p_d(t)` with exact derivatives.
pub trait Trajectory: fmt::Debug + Send + Sync {
    /// `p_d(t)` and its derivatives up to `order` (higher ones may be zero).
    fn eval(&self, t: f64, order: Order) -> Jet;
}

/// Eq. 18: the path of a unicycle with constant speed `V_d` and turn rate `ω_d`
/// from a start pose: a circle of radius `V_d/ω_d`, or a straight line when `ω_d = 0`.
///
/// Built through [`Circle::new`], which checks it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Circle {
    start: [f64; 2],
    heading: f64,
    speed: f64,
    turn_rate: f64,
}

impl Circle {
    /// Checks speed and turn rate are finite and the speed non-negative.
    pub fn new(
        start: [f64; 2],
        heading: f64,
        speed: f64,
        turn_rate: f64,
    ) -> Result<Circle, ReferenceError> {
        finite("start.x", start[0])?;
        finite("start.y", start[1])?;
        finite("start.theta", heading)?;
        finite("speed", speed)?;
        finite("turn_rate", turn_rate)?;
        require(
            "speed",
            speed,
            speed >= 0.0,
            "must be ≥ 0 (the leader moves forward)",
        )?;
        Ok(Circle {
            start,
            heading,
            speed,
            turn_rate,
        })
    }

    /// Start position `(x_d(0), y_d(0))`, m.
    #[inline]
    pub const fn start(&self) -> [f64; 2] {
        self.start
    }

    /// Start heading `θ_d(0)`, rad.
    #[inline]
    pub const fn heading(&self) -> f64 {
        self.heading
    }

    /// `V_d ≥ 0`, m/s.
    #[inline]
    pub const fn speed(&self) -> f64 {
        self.speed
    }

    /// `ω_d`, rad/s (0: straight line).
    #[inline]
    pub const fn turn_rate(&self) -> f64 {
        self.turn_rate
    }
}

impl Trajectory for Circle {
    fn eval(&self, t: f64, order: Order) -> Jet {
        let (v, w) = (self.speed, self.turn_rate);
        let half = 0.5 * w * t;
        // p(t) − p(0) = (V/ω)[sin θ − sin θ0, cos θ0 − cos θ], written without the
        // division so that it is exact for ω → 0 (straight line).
        let chord = v * t * sinc(half);
        let (sm, cm) = (self.heading + half).sin_cos();
        let (s, c) = (self.heading + w * t).sin_cos();
        let mut jet = Jet {
            p: [self.start[0] + chord * cm, self.start[1] + chord * sm],
            dp: [v * c, v * s],
            ddp: [-v * w * s, v * w * c],
            ..Jet::default()
        };
        if order == Order::Four {
            let w2 = w * w;
            jet.d3p = [-v * w2 * c, -v * w2 * s];
            jet.d4p = [v * w2 * w * s, -v * w2 * w * c];
        }
        jet
    }
}

impl Circle {
    /// [`Circle::eval`] to [`Order::Two`] of `W` circles at once, circle
    /// `k` at `t.0[k]`: `(p, ṗ, p̈)` per lane, the sines and cosines by the
    /// branch-free [`Lanes::sin_cos`] (within 2 ulp of the platform's, so
    /// within a few ulp of [`Circle::eval`]), the chord's `sinc` as
    /// [`sinc`] puts it. What a batch of environments behind circles
    /// evaluates each step (`learn`).
    #[inline(always)]
    pub fn jets<const W: usize>(
        circles: [&Circle; W],
        t: Lanes<W>,
    ) -> ([Lanes<W>; 2], [Lanes<W>; 2], [Lanes<W>; 2]) {
        let lane = |f: fn(&Circle) -> f64| Lanes(circles.map(f));
        let (v, w, heading) = (
            lane(|c| c.speed),
            lane(|c| c.turn_rate),
            lane(|c| c.heading),
        );
        let half = w * t * 0.5;
        let (sh, _) = half.sin_cos();
        // sinc(half), as `math::sinc`: its series below 1e-4.
        let small = half.abs().lt(Lanes::splat(1e-4));
        let series = -(half * half / 6.0) + 1.0;
        let sinc = Lanes::select(
            small,
            series,
            sh / Lanes::select(small, Lanes::splat(1.0), half),
        );
        let chord = v * t * sinc;
        let (sm, cm) = (heading + half).sin_cos();
        let (s, c) = (heading + w * t).sin_cos();
        let vw = v * w;
        (
            [
                lane(|c| c.start[0]) + chord * cm,
                lane(|c| c.start[1]) + chord * sm,
            ],
            [v * c, v * s],
            [-(vw * s), vw * c],
        )
    }
}

/// Eq. 19: the lemniscate of Bernoulli traversed at angular rate `c`,
/// `x = a cos(ct)/(1 + sin²(ct))`, `y = a sin(ct) cos(ct)/(1 + sin²(ct))`,
/// shifted by `center`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Lemniscate {
    /// Half-width `a`, m.
    pub a: f64,
    /// Rate `c`, rad/s (one full figure-eight takes `2π/c`).
    pub c: f64,
    /// Centre of the figure, m.
    pub center: [f64; 2],
}

impl Lemniscate {
    /// Checks `a > 0` and `c` finite and non-zero.
    pub fn new(a: f64, c: f64, center: [f64; 2]) -> Result<Lemniscate, ReferenceError> {
        finite("a", a)?;
        finite("c", c)?;
        finite("center.x", center[0])?;
        finite("center.y", center[1])?;
        require("a", a, a > 0.0, "must be > 0")?;
        require("c", c, c != 0.0, "must be non-zero")?;
        Ok(Lemniscate { a, c, center })
    }

    fn xy<D: DualNum<Primitive = f64> + Copy>(&self, t: D) -> [D; 2] {
        let (s, c) = (t * self.c).sin_cos();
        let k = (s * s + 1.0).recip() * self.a;
        [c * k + self.center[0], s * c * k + self.center[1]]
    }
}

impl Trajectory for Lemniscate {
    fn eval(&self, t: f64, order: Order) -> Jet {
        jet_by_dual(t, order, |t| self.xy(t), |t| self.xy(t))
    }
}

/// Derivatives of a generic planar function of time by dual numbers:
/// `Dual2<f64>` for order two, nested `Dual2<Dual2<f64>>` for order four.
fn jet_by_dual(
    t: f64,
    order: Order,
    f2: impl Fn(Dual2<f64>) -> [Dual2<f64>; 2],
    f4: impl Fn(Dual2<Dual2<f64>>) -> [Dual2<Dual2<f64>>; 2],
) -> Jet {
    match order {
        Order::Two => {
            let r = f2(Dual2::new(t, 1.0, 0.0));
            Jet {
                p: [r[0].re, r[1].re],
                dp: [r[0].v1, r[1].v1],
                ddp: [r[0].v2, r[1].v2],
                ..Jet::default()
            }
        }
        Order::Four => {
            let one = Dual2::new(1.0, 0.0, 0.0);
            let zero = Dual2::new(0.0, 0.0, 0.0);
            let r = f4(Dual2::new(Dual2::new(t, 1.0, 0.0), one, zero));
            // r.re = (f, f', f''), r.v1 = (f', f'', f'''), r.v2 = (f'', f''', f'''').
            Jet {
                p: [r[0].re.re, r[1].re.re],
                dp: [r[0].re.v1, r[1].re.v1],
                ddp: [r[0].re.v2, r[1].re.v2],
                d3p: [r[0].v1.v2, r[1].v1.v2],
                d4p: [r[0].v2.v2, r[1].v2.v2],
            }
        }
    }
}

/// Eqs. 17/20: the non-feasible cubic `x = s (t − t₀)³`,
/// `y = 0` before `t₀` and `s (t − t₀)³` after. C² in time (its 3rd derivative
/// jumps from 0 to `6s` in `y` at `t₀`); at `t₀` the path turns by 45° at zero
/// speed, which no unicycle can do.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Cubic {
    /// Scale `s` (eq. 17: 1; eq. 20: 1/16), m/s³.
    pub scale: f64,
    /// Switch time `t₀` (eq. 17: 1 s; eq. 20: 4 s), s.
    pub t_switch: f64,
}

impl Cubic {
    /// Checks the parameters are finite.
    pub fn new(scale: f64, t_switch: f64) -> Result<Cubic, ReferenceError> {
        finite("scale", scale)?;
        finite("t_switch", t_switch)?;
        Ok(Cubic { scale, t_switch })
    }
}

impl Trajectory for Cubic {
    fn eval(&self, t: f64, _order: Order) -> Jet {
        let s = self.scale;
        let d = t - self.t_switch;
        let x = [s * d * d * d, 3.0 * s * d * d, 6.0 * s * d, 6.0 * s, 0.0];
        let y = if t < self.t_switch { [0.0; 5] } else { x };
        Jet::from_axes(x, y)
    }
}

/// A path through timed waypoints `(t, x, y)`, interpolated per coordinate by a
/// septic spline: C⁶ between waypoints, at rest (zero velocity, acceleration and
/// jerk) at the first and last one, so the reference is C³ over all time.
/// Before the first and after the last time the reference stands still there.
#[derive(Debug, Clone, PartialEq)]
pub struct Waypoints {
    points: Vec<[f64; 3]>,
    x: Septic,
    y: Septic,
}

impl Waypoints {
    /// Shortest time between consecutive waypoints, s: closer ones ask the
    /// spline for absurd speeds and its derivatives for absurd values.
    pub const MIN_GAP: f64 = crate::reference::spline::MIN_GAP;
    /// Largest speed of the spline, and so of the average between
    /// consecutive waypoints, m/s: the plausible speed of a reference (the
    /// scenario's `reference.*.speed`).
    pub const MAX_SPEED: f64 = crate::reference::spline::MAX_SPEED;
    /// Times per segment the spline's speed is checked against [`Self::MAX_SPEED`].
    pub const SPEED_SAMPLES: usize = 16;

    /// Builds the spline through `points`, each `[t, x, y]`, refusing fewer
    /// than two, a coordinate that is not finite, times that do not increase
    /// by at least [`Self::MIN_GAP`], an average speed between consecutive
    /// points above [`Self::MAX_SPEED`], and a spline that overshoots it.
    pub fn new(points: Vec<[f64; 3]>) -> Result<Waypoints, ReferenceError> {
        check_waypoints(&points)?;
        let t: Vec<f64> = points.iter().map(|p| p[0]).collect();
        let xs: Vec<f64> = points.iter().map(|p| p[1]).collect();
        let ys: Vec<f64> = points.iter().map(|p| p[2]).collect();
        let w = Waypoints {
            x: Septic::new(&t, &xs),
            y: Septic::new(&t, &ys),
            points,
        };
        w.check_speed()?;
        Ok(w)
    }

    /// Refuses a spline faster than [`Self::MAX_SPEED`] anywhere (sampled
    /// [`Self::SPEED_SAMPLES`] times per segment): waypoints unevenly spaced
    /// in time make it overshoot far beyond their average speeds.
    fn check_speed(&self) -> Result<(), ReferenceError> {
        for (k, pair) in self.points.windows(2).enumerate() {
            let (a, b) = (pair[0][0], pair[1][0]);
            for s in 1..Self::SPEED_SAMPLES {
                let t = a + (b - a) * s as f64 / Self::SPEED_SAMPLES as f64;
                let speed = self.x.eval(t)[1].hypot(self.y.eval(t)[1]);
                // NaN (a spline that is not finite) is refused too.
                if speed.is_nan() || speed > Self::MAX_SPEED {
                    return Err(ReferenceError::WaypointsOvershoot {
                        index: k + 2,
                        t: b,
                        previous: a,
                        at: t,
                        speed,
                        max_speed: Self::MAX_SPEED,
                    });
                }
            }
        }
        Ok(())
    }

    /// The waypoints, `[t, x, y]` each.
    pub fn points(&self) -> &[[f64; 3]] {
        &self.points
    }
}

impl Trajectory for Waypoints {
    fn eval(&self, t: f64, _order: Order) -> Jet {
        Jet::from_axes(self.x.eval(t), self.y.eval(t))
    }
}

/// Any of the built-in references, or a user-supplied one.
#[derive(Debug, Clone)]
pub enum Reference {
    /// Eq. 18 (and straight lines).
    Circle(Circle),
    /// Eq. 19.
    Lemniscate(Lemniscate),
    /// Eqs. 17/20.
    Cubic(Cubic),
    /// Timed waypoints through a septic spline, C³ over all time.
    Waypoints(Waypoints),
    /// Anything else implementing [`Trajectory`].
    Custom(Arc<dyn Trajectory>),
}

impl Reference {
    /// Whether the path keeps moving at every instant, so its heading is
    /// defined at every instant: a circle or line with a speed, a
    /// lemniscate. Cubics and waypoints stand still at times (and a custom
    /// trajectory is not known to move).
    pub fn keeps_moving(&self) -> bool {
        match self {
            Reference::Circle(r) => r.speed() > STANDSTILL,
            Reference::Lemniscate(_) => true,
            Reference::Cubic(_) | Reference::Waypoints(_) | Reference::Custom(_) => false,
        }
    }
}

impl Trajectory for Reference {
    #[inline]
    fn eval(&self, t: f64, order: Order) -> Jet {
        match self {
            Reference::Circle(r) => r.eval(t, order),
            Reference::Lemniscate(r) => r.eval(t, order),
            Reference::Cubic(r) => r.eval(t, order),
            Reference::Waypoints(r) => r.eval(t, order),
            Reference::Custom(r) => r.eval(t, order),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::FRAC_PI_2;

    #[test]
    fn circle_starts_at_its_pose_and_closes_a_lap() {
        let c = Circle::new([1.0, 2.0], 0.3, 0.5, 0.1).unwrap();
        let j0 = c.eval(0.0, Order::Two);
        assert_eq!(j0.p, [1.0, 2.0]);
        assert!((j0.heading() - 0.3).abs() < 1e-15);
        let lap = c.eval(2.0 * std::f64::consts::PI / 0.1, Order::Two);
        assert!((lap.p[0] - 1.0).abs() < 1e-12 && (lap.p[1] - 2.0).abs() < 1e-12);
        assert!((j0.speed() - 0.5).abs() < 1e-15 && (j0.turn_rate() - 0.1).abs() < 1e-15);
    }

    #[test]
    fn straight_line_is_the_zero_turn_circle() {
        let c = Circle::new([0.0, 0.0], FRAC_PI_2, 2.0, 0.0).unwrap();
        let j = c.eval(3.0, Order::Four);
        assert!(j.p[0].abs() < 1e-12 && (j.p[1] - 6.0).abs() < 1e-12);
        assert_eq!(j.ddp, [0.0, 0.0]);
        assert_eq!(j.turn_rate(), 0.0);
        // A gentle curve agrees with the closed form (V/ω)(sin θ − sin θ₀) without cancellation.
        let g = Circle::new([0.0, 0.0], 0.0, 1.0, 1e-6).unwrap();
        let p = g.eval(10.0, Order::Two).p;
        assert!((p[0] - (1e-5f64).sin() / 1e-6).abs() < 1e-12);
    }

    #[test]
    fn lemniscate_matches_eq_19_and_the_papers_start_pose() {
        let l = Lemniscate::new(10.0, 0.1, [0.0, 0.0]).unwrap();
        let j = l.eval(0.0, Order::Two);
        assert_eq!(j.p, [10.0, 0.0]);
        assert!(
            (j.heading() - FRAC_PI_2).abs() < 1e-12,
            "starts heading 90°"
        );
        let t: f64 = 7.3;
        let (s, c) = (0.1 * t).sin_cos();
        let p = l.eval(t, Order::Two).p;
        assert!((p[0] - 10.0 * c / (1.0 + s * s)).abs() < 1e-12);
        assert!((p[1] - 10.0 * s * c / (1.0 + s * s)).abs() < 1e-12);
    }

    #[test]
    fn order_four_agrees_with_order_two_on_common_terms() {
        let l = Lemniscate::new(2.4, 0.02, [0.5, -0.5]).unwrap();
        let (a, b) = (l.eval(12.0, Order::Two), l.eval(12.0, Order::Four));
        assert_eq!(a.p, b.p);
        assert_eq!(a.dp, b.dp);
        assert_eq!(a.ddp, b.ddp);
    }

    #[test]
    fn cubic_matches_eq_20() {
        let c = Cubic::new(1.0 / 16.0, 4.0).unwrap();
        let j = c.eval(0.0, Order::Two);
        assert_eq!(j.p, [-4.0, 0.0]);
        let j = c.eval(6.0, Order::Two);
        assert_eq!(j.p, [0.5, 0.5]);
        assert_eq!(j.dp, [0.75, 0.75]);
        let at = c.eval(4.0, Order::Two);
        assert_eq!(at.speed(), 0.0);
    }

    #[test]
    fn invalid_parameters_are_refused() {
        assert!(Lemniscate::new(-1.0, 0.1, [0.0, 0.0]).is_err());
        assert!(Lemniscate::new(1.0, 0.0, [0.0, 0.0]).is_err());
        assert!(Circle::new([0.0, 0.0], 0.0, -1.0, 0.1).is_err());
        assert!(Circle::new([0.0, 0.0], 0.0, 1.0, f64::NAN).is_err());
        assert!(Cubic::new(f64::INFINITY, 1.0).is_err());
    }

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig::with_cases(256))]

        /// Eight circles in lanes are the eight circles one by one, to a few
        /// ulp of the position's scale: turn rates from exactly zero (a line)
        /// through the series' edge to fast turns, times to an hour.
        #[test]
        fn circles_in_lanes_are_the_circles(
            raw in proptest::collection::vec(
                (-50.0..50.0f64, -50.0..50.0f64, -10.0..10.0f64, 0.0..3.0f64,
                 proptest::prop_oneof![proptest::strategy::Just(0.0), -1e-3..1e-3f64, -3.0..3.0f64],
                 0.0..3600.0f64),
                8),
        ) {
            let circles: Vec<Circle> = raw.iter().map(|&(x, y, h, v, w, _)| Circle::new([x, y], h, v, w).unwrap()).collect();
            let t = Lanes(std::array::from_fn::<f64, 8, _>(|k| raw[k].5));
            let (p, dp, ddp) = Circle::jets(std::array::from_fn(|k| &circles[k]), t);
            for (k, c) in circles.iter().enumerate() {
                let j = c.eval(t.0[k], Order::Two);
                let scale = 1.0 + j.p[0].abs().max(j.p[1].abs()) + c.speed() * t.0[k];
                for (got, want, tol) in [
                    (p[0].0[k], j.p[0], 1e-14 * scale), (p[1].0[k], j.p[1], 1e-14 * scale),
                    (dp[0].0[k], j.dp[0], 1e-14), (dp[1].0[k], j.dp[1], 1e-14),
                    (ddp[0].0[k], j.ddp[0], 1e-14), (ddp[1].0[k], j.ddp[1], 1e-14),
                ] {
                    proptest::prop_assert!((got - want).abs() <= tol, "circle {k}: {got} vs {want}");
                }
            }
        }
    }
}
