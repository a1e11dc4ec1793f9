//! Domain types that cannot hold an invalid value (issue 21): every checked
//! constructor refuses what it must (naming the field), every value it accepts
//! round-trips through serde (TOML and JSON) unchanged, and deserialising an
//! invalid document fails with the constructor's own message.
#![allow(clippy::unwrap_used)] // tests fail loudly by design

mod common;

use echelon::ParamError;
use echelon::base::{AccelLimit, VelocityBase, VelocityRobot};
use echelon::control::Gains;
use echelon::lycomp::{FitCoefficients, LyComp, LyDerivatives, Placement, PlacementSpec};
use echelon::model::{RobotParams, RobotParamsSpec};
use echelon::odometry::{ErrorModel, OdometrySpec};
use echelon::reference::Circle;
use echelon::safety::Obstacle;
use proptest::prelude::*;
use serde::Serialize;
use serde::de::DeserializeOwned;

/// A finite number > 0, from tiny to huge.
fn positive() -> impl Strategy<Value = f64> {
    prop_oneof![
        1e-3..1e4f64,
        prop::num::f64::POSITIVE | prop::num::f64::NORMAL,
    ]
}

/// A finite number ≥ 0.
fn non_negative() -> impl Strategy<Value = f64> {
    prop_oneof![Just(0.0), positive()]
}

/// A number that is not finite.
fn not_finite() -> impl Strategy<Value = f64> {
    prop_oneof![Just(f64::NAN), Just(f64::INFINITY), Just(f64::NEG_INFINITY)]
}

/// A number that is not a finite number > 0.
fn not_positive() -> impl Strategy<Value = f64> {
    prop_oneof![
        Just(0.0),
        Just(-0.0),
        prop::num::f64::NEGATIVE | prop::num::f64::NORMAL | prop::num::f64::SUBNORMAL,
        not_finite(),
    ]
}

/// A number that is not a finite number ≥ 0.
fn negative_or_not_finite() -> impl Strategy<Value = f64> {
    prop_oneof![
        prop::num::f64::NEGATIVE | prop::num::f64::NORMAL | prop::num::f64::SUBNORMAL,
        not_finite(),
    ]
}

/// A decimal with few digits (`12.345`): JSON parses it back exactly (serde_json
/// parses arbitrary floats to within one ulp only, without `float_roundtrip`).
fn decimal(lo: u32) -> impl Strategy<Value = f64> {
    (lo..1_000_000u32, 0..6i32).prop_map(|(k, e)| f64::from(k) / 10f64.powi(e))
}

/// `value` through a TOML document and back.
fn toml_round_trip<T: Serialize + DeserializeOwned>(value: &T) -> T {
    toml::from_str(&toml::to_string(value).unwrap()).unwrap()
}

/// `value` through a JSON document and back.
fn json_round_trip<T: Serialize + DeserializeOwned>(value: &T) -> T {
    serde_json::from_str(&serde_json::to_string(value).unwrap()).unwrap()
}

/// `value` through a JSON tree and back (no text: exact for any float).
fn json_value_round_trip<T: Serialize + DeserializeOwned>(value: &T) -> T {
    serde_json::from_value(serde_json::to_value(value).unwrap()).unwrap()
}

/// The document `value` serialises to with `field` set to `bad`, as TOML
/// (which can write NaN and infinities).
fn toml_with<T: Serialize>(value: &T, field: &str, bad: f64) -> String {
    let mut table = toml::Table::try_from(value).unwrap();
    table.insert(field.to_owned(), toml::Value::Float(bad));
    toml::to_string(&table).unwrap()
}

/// Deserialising `doc` fails with exactly the constructor's message.
fn refused_as<T: DeserializeOwned + std::fmt::Debug>(
    doc: &str,
    expected: &ParamError,
) -> Result<(), TestCaseError> {
    let e = toml::from_str::<T>(doc).unwrap_err();
    prop_assert_eq!(e.message(), expected.to_string(), "{}", doc);
    Ok(())
}

/// `RobotParamsSpec`'s fields in order, without the torque limit.
type RobotArgs = (f64, f64, f64, f64, f64, f64);

fn robot(a: RobotArgs) -> Result<RobotParams, ParamError> {
    RobotParams::new(RobotParamsSpec {
        mass: a.0,
        linear_friction: a.1,
        inertia: a.2,
        angular_friction: a.3,
        half_wheelbase: a.4,
        wheel_radius: a.5,
        torque_limit: None,
    })
}

fn robot_args() -> impl Strategy<Value = RobotArgs> {
    (
        positive(),
        non_negative(),
        positive(),
        non_negative(),
        positive(),
        positive(),
    )
}

const ROBOT_FIELDS: [&str; 6] = [
    "mass",
    "linear_friction",
    "inertia",
    "angular_friction",
    "half_wheelbase",
    "wheel_radius",
];

/// `a` with its `i`-th argument replaced.
fn set(a: RobotArgs, i: usize, v: f64) -> RobotArgs {
    let mut x = [a.0, a.1, a.2, a.3, a.4, a.5];
    x[i] = v;
    (x[0], x[1], x[2], x[3], x[4], x[5])
}

proptest! {
    /// Valid arguments give a robot whose getters return them; any other
    /// torque limit than a finite number > 0 is refused.
    #[test]
    fn robot_accepts_what_is_physical(a in robot_args(), limit in positive()) {
        let p = robot(a).unwrap();
        prop_assert_eq!(
            (p.mass(), p.linear_friction(), p.inertia(), p.angular_friction(), p.half_wheelbase(), p.wheel_radius()),
            a
        );
        prop_assert_eq!(p.torque_limit(), None);
        prop_assert_eq!(p.with_torque_limit(Some(limit)).unwrap().torque_limit(), Some(limit));
    }

    /// A non-positive or non-finite mass, inertia, half wheelbase or wheel
    /// radius, a negative or non-finite friction, or a torque limit that is
    /// not a finite number > 0 is refused, naming the field.
    #[test]
    fn robot_refuses_what_is_not(
        a in robot_args(),
        which in 0..6usize,
        not_pos in not_positive(),
        neg in negative_or_not_finite(),
    ) {
        let friction = which == 1 || which == 3;
        let bad = if friction { neg } else { not_pos };
        let e = robot(set(a, which, bad)).unwrap_err();
        prop_assert_eq!(e.field, ROBOT_FIELDS[which]);
        let e = robot(a).unwrap().with_torque_limit(Some(not_pos)).unwrap_err();
        prop_assert_eq!(e.field, "torque_limit");
    }

    /// Every robot round-trips through TOML and JSON unchanged.
    #[test]
    fn robot_round_trips(a in robot_args(), limit in prop::option::of(positive())) {
        let p = robot(a).unwrap().with_torque_limit(limit).unwrap();
        prop_assert_eq!(toml_round_trip(&p), p);
        prop_assert_eq!(json_value_round_trip(&p), p);
    }

    /// Robots with decimal values round-trip through JSON text unchanged.
    #[test]
    fn robot_round_trips_as_json_text(
        m in decimal(1), eta in decimal(0), j in decimal(1), psi in decimal(0),
        l in decimal(1), r in decimal(1), limit in prop::option::of(decimal(1)),
    ) {
        let p = robot((m, eta, j, psi, l, r)).unwrap().with_torque_limit(limit).unwrap();
        prop_assert_eq!(json_round_trip(&p), p);
    }

    /// A document with an impossible value does not deserialise: the error is
    /// the constructor's.
    #[test]
    fn robot_document_refused(
        a in robot_args(),
        which in 0..7usize,
        not_pos in not_positive(),
        neg in negative_or_not_finite(),
    ) {
        let p = robot(a).unwrap();
        let (bad, expected) = if which == 6 {
            (not_pos, p.with_torque_limit(Some(not_pos)).unwrap_err())
        } else {
            let bad = if which == 1 || which == 3 { neg } else { not_pos };
            (bad, robot(set(a, which, bad)).unwrap_err())
        };
        let field = if which == 6 { "torque_limit" } else { ROBOT_FIELDS[which] };
        refused_as::<RobotParams>(&toml_with(&p, field, bad), &expected)?;
    }
}

#[test]
fn robot_serialised_form_is_unchanged() {
    let json = serde_json::to_string(&RobotParams::AGENT1).unwrap();
    assert_eq!(
        json,
        r#"{"mass":27.0,"linear_friction":180.0,"inertia":1.42,"angular_friction":9.47,"half_wheelbase":0.23,"wheel_radius":0.101,"torque_limit":null}"#
    );
    let bad = json.replace("27.0", "-27.0");
    let e = serde_json::from_str::<RobotParams>(&bad).unwrap_err();
    assert!(e.to_string().starts_with("mass = -27: must be > 0"), "{e}");
    let missing = r#"{"mass":27.0}"#;
    assert!(serde_json::from_str::<RobotParams>(missing).is_err());
}

/// A limit: a finite number > 0 or infinite (no limit).
fn limit() -> impl Strategy<Value = f64> {
    prop_oneof![positive(), Just(f64::INFINITY)]
}

/// A limit that is not one: zero, negative (even −∞) or NaN.
fn not_a_limit() -> impl Strategy<Value = f64> {
    prop_oneof![
        Just(0.0),
        Just(-0.0),
        Just(f64::NAN),
        Just(f64::NEG_INFINITY),
        prop::num::f64::NEGATIVE | prop::num::f64::NORMAL | prop::num::f64::SUBNORMAL,
    ]
}

/// `VelocityBaseSpec`'s numbers in order: lags ≥ 0, speed limits, and acceleration
/// limits that are finite only on a lagged axis.
fn base_args() -> impl Strategy<Value = [f64; 6]> {
    (
        non_negative(),
        non_negative(),
        limit(),
        limit(),
        limit(),
        limit(),
    )
        .prop_map(|(tv, tw, v, w, a, alpha)| {
            let a = if tv > 0.0 { a } else { f64::INFINITY };
            let alpha = if tw > 0.0 { alpha } else { f64::INFINITY };
            [tv, tw, v, w, a, alpha]
        })
}

fn base(x: [f64; 6]) -> Result<VelocityBase, ParamError> {
    common::velocity_base(x, AccelLimit::Joint)
}

const BASE_FIELDS: [&str; 6] = [
    "tau_v",
    "tau_omega",
    "v_max",
    "omega_max",
    "a_max",
    "alpha_max",
];

proptest! {
    /// Valid arguments give a base whose getters return them (joint
    /// acceleration limits unless asked otherwise), and a robot on it with any
    /// wheels of finite size > 0.
    #[test]
    fn base_accepts_what_is_possible(
        x in base_args(), per_axis in any::<bool>(), l in positive(), r in positive(),
    ) {
        let b = base(x).unwrap();
        prop_assert_eq!(
            [b.tau_v(), b.tau_omega(), b.v_max(), b.omega_max(), b.a_max(), b.alpha_max()],
            x
        );
        prop_assert_eq!(b.accel(), AccelLimit::Joint);
        let accel = if per_axis { AccelLimit::PerAxis } else { AccelLimit::Joint };
        prop_assert_eq!(b.with_accel(accel).accel(), accel);
        let robot = VelocityRobot::new(b, l, r).unwrap();
        prop_assert_eq!((robot.base(), robot.half_wheelbase(), robot.wheel_radius()), (b, l, r));
    }

    /// A negative or non-finite lag, a limit that is zero, negative or NaN, a
    /// finite acceleration limit on an axis without lag, or a wheel that is
    /// not a finite number > 0 is refused, naming the field.
    #[test]
    fn base_refuses_what_is_not(
        x in base_args(),
        which in 0..6usize,
        bad_lag in negative_or_not_finite(),
        bad_limit in not_a_limit(),
        finite_limit in positive(),
        bad_wheel in not_positive(),
    ) {
        let mut y = x;
        y[which] = if which < 2 { bad_lag } else { bad_limit };
        prop_assert_eq!(base(y).unwrap_err().field, BASE_FIELDS[which]);
        // An axis without lag takes no finite acceleration limit.
        let axis = which % 2;
        let mut z = x;
        z[axis] = 0.0;
        z[4 + axis] = finite_limit;
        prop_assert_eq!(base(z).unwrap_err().field, BASE_FIELDS[4 + axis]);
        let b = base(x).unwrap();
        prop_assert_eq!(VelocityRobot::new(b, bad_wheel, 0.05).unwrap_err().field, "half_wheelbase");
        prop_assert_eq!(VelocityRobot::new(b, 0.15, bad_wheel).unwrap_err().field, "wheel_radius");
    }
}

proptest! {
    /// Gains are two finite numbers > 0: those are kept as given, anything
    /// else is refused naming `ke` or `kz`.
    #[test]
    fn gains_are_positive(ke in positive(), kz in positive(), bad in not_positive()) {
        let g = Gains::new(ke, kz).unwrap();
        prop_assert_eq!((g.ke(), g.kz()), (ke, kz));
        prop_assert_eq!(Gains::new(bad, kz).unwrap_err().field, "ke");
        prop_assert_eq!(Gains::new(ke, bad).unwrap_err().field, "kz");
    }
}

/// A finite offset, m.
fn offset() -> impl Strategy<Value = f64> {
    prop_oneof![-5.0..5.0f64, -1e6..1e6f64]
}

fn derivatives() -> impl Strategy<Value = LyDerivatives> {
    prop_oneof![Just(LyDerivatives::Neglect), Just(LyDerivatives::Exact)]
}

proptest! {
    /// Finite offsets and `L > 0` with `L_X = L_Xoff + L > 0` give a placement
    /// that keeps them (and the eq. 6 fit for its `L_Xoff`); in the fit's
    /// range the fit is accepted too.
    #[test]
    fn placement_accepts_what_keeps_lx_positive(
        lx in offset(), ly in offset(), l in positive(), d in derivatives(),
        exact in any::<bool>(), in_range in 0.1..0.9f64,
    ) {
        prop_assume!(lx + l > 0.0);
        let comp = if exact { LyComp::Exact } else { LyComp::None };
        let p = Placement::new(PlacementSpec { lx_off: lx, ly_off: ly, l, comp, derivatives: d }).unwrap();
        prop_assert_eq!((p.lx_off(), p.ly_off(), p.l(), p.lycomp(), p.derivatives()), (lx, ly, l, comp, d));
        prop_assert_eq!(p.fit(), FitCoefficients::paper(lx));
        prop_assert!(p.lx() > 0.0);
        let f = Placement::new(PlacementSpec { lx_off: in_range, ly_off: ly, l, comp: LyComp::Fit, derivatives: d }).unwrap();
        prop_assert_eq!(f.lycomp(), LyComp::Fit);
        let t = Placement::tracking(l).unwrap();
        prop_assert_eq!((t.lx_off(), t.ly_off(), t.l()), (0.0, 0.0, l));
    }

    /// `L` that is not a finite number > 0, an offset that is not finite, or
    /// `L_X ≤ 0` is refused, naming `l`, `offset.x` or `offset.y`.
    #[test]
    fn placement_refuses_what_does_not(
        lx in offset(), ly in offset(), l in positive(), d in derivatives(),
        bad_l in not_positive(), bad_offset in not_finite(), behind in 0.0..10.0f64,
    ) {
        prop_assume!(lx + l > 0.0);
        let new = |lx, ly, l| Placement::new(PlacementSpec { lx_off: lx, ly_off: ly, l, comp: LyComp::Exact, derivatives: d });
        prop_assert_eq!(new(lx, ly, bad_l).unwrap_err().field, "l");
        prop_assert_eq!(Placement::tracking(bad_l).unwrap_err().field, "l");
        prop_assert_eq!(new(bad_offset, ly, l).unwrap_err().field, "offset.x");
        prop_assert_eq!(new(lx, bad_offset, l).unwrap_err().field, "offset.y");
        prop_assert_eq!(new(-l - behind, ly, l).unwrap_err().field, "offset.x");
    }
}

proptest! {
    /// A circle from any finite start at a finite speed ≥ 0 and finite turn
    /// rate keeps them; a value that is not finite, or a negative speed, is
    /// refused naming its field.
    #[test]
    fn circle_checks_its_values(
        x in offset(), y in offset(), heading in offset(), speed in non_negative(),
        turn_rate in offset(), bad in not_finite(), backwards in positive(),
    ) {
        let c = Circle::new([x, y], heading, speed, turn_rate).unwrap();
        prop_assert_eq!((c.start(), c.heading(), c.speed(), c.turn_rate()), ([x, y], heading, speed, turn_rate));
        let field = |r: Result<Circle, echelon::ReferenceError>| match r {
            Err(echelon::ReferenceError::Param(e)) => e.field,
            other => panic!("{other:?}"),
        };
        prop_assert_eq!(field(Circle::new([bad, y], heading, speed, turn_rate)), "start.x");
        prop_assert_eq!(field(Circle::new([x, bad], heading, speed, turn_rate)), "start.y");
        prop_assert_eq!(field(Circle::new([x, y], bad, speed, turn_rate)), "start.theta");
        prop_assert_eq!(field(Circle::new([x, y], heading, bad, turn_rate)), "speed");
        prop_assert_eq!(field(Circle::new([x, y], heading, -backwards, turn_rate)), "speed");
        prop_assert_eq!(field(Circle::new([x, y], heading, speed, bad)), "turn_rate");
    }

    /// An obstacle has a finite centre and a radius that is a finite number > 0.
    #[test]
    fn obstacle_checks_its_values(
        x in offset(), y in offset(), r in positive(), bad in not_finite(), bad_r in not_positive(),
    ) {
        let o = Obstacle::new(x, y, r).unwrap();
        prop_assert_eq!((o.x(), o.y(), o.r()), (x, y, r));
        prop_assert_eq!(Obstacle::new(bad, y, r).unwrap_err().field, "x");
        prop_assert_eq!(Obstacle::new(x, bad, r).unwrap_err().field, "y");
        prop_assert_eq!(Obstacle::new(x, y, bad_r).unwrap_err().field, "r");
    }
}

proptest! {
    /// An odometry spec has a period that is a finite number > 0 and a valid
    /// error model: those are kept, anything else is refused naming the field.
    #[test]
    fn odometry_spec_checks_its_parts(
        period in positive(), bad in not_positive(), ratio in positive(), bad_ratio in not_positive(),
    ) {
        let errors = ErrorModel::systematic(ratio, 1.0).unwrap();
        let spec = OdometrySpec::new(period, errors, None).unwrap();
        prop_assert_eq!((spec.period(), spec.errors(), spec.fixes()), (period, errors, None));
        prop_assert_eq!(OdometrySpec::new(bad, errors, None).unwrap_err().field, "period");
        prop_assert_eq!(ErrorModel::systematic(1.0, bad_ratio).unwrap_err().field, "wheelbase_ratio");
    }
}
