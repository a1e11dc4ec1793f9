use super::*;
use echelon::odometry::bound::KinematicTheorem2;
use echelon::odometry::{FixSchedule, Fusion};
use echelon_ros2::keys::topic_key;
use echelon_ros2::msgs::{ODOMETRY, Time};
use proptest::prelude::*;

const TOPIC: &str = "/mocap/robot1/pose";

fn source(message: FixMessage, frame_origin: Pose, gate: bool) -> FixSource {
    FixSource {
        topic: TOPIC.to_owned(),
        message,
        frame: "map".to_owned(),
        frame_origin,
        timeout: None,
        tolerance: None,
        gate,
    }
}

fn spec(fusion: Fusion, position_noise: f64, heading_noise: Option<f64>) -> FixSpec {
    FixSpec::new(FixSchedule::Period(0.1), fusion)
        .and_then(|f| f.with_noise(position_noise, heading_noise))
        .unwrap()
}

const MODEL: OdometryModel = OdometryModel {
    errors: ErrorModel::PERFECT,
    wheels: (0.1, 0.03),
    sample_period: 0.02,
    top_speed: 0.5,
};

fn input(src: FixSource, spec: FixSpec, model: OdometryModel, origin: Pose) -> FixInput {
    FixInput::new(1, src, KeyScheme::RmwZenoh, &spec, model, origin, 1.0)
        .unwrap_or_else(|e| panic!("{e}"))
}

fn key(message: FixMessage) -> String {
    topic_key(KeyScheme::RmwZenoh, 0, TOPIC, fix_type(message))
}

fn pose_msg(p: &Pose, stamp_ns: i64, frame: &str) -> Vec<u8> {
    PoseStamped::planar(p.x, p.y, p.theta, Time::from_nanos(stamp_ns), frame).to_cdr()
}

fn pose() -> impl Strategy<Value = Pose> {
    (-20.0..20.0f64, -20.0..20.0f64, -3.1..3.1f64).prop_map(|(x, y, theta)| Pose { x, y, theta })
}

/// A robot driven along arcs from `start` (world): its true world poses
/// every 20 ms and their stamps (ns).
fn drive(start: Pose, arcs: &[(f64, f64)]) -> Vec<(i64, Pose)> {
    let mut p = start;
    let mut out = vec![(20_000_000, p)];
    for (k, &(delta, big_theta)) in arcs.iter().enumerate() {
        p = echelon::odometry::arc_update(&p, delta, big_theta);
        out.push((20_000_000 * (k as i64 + 2), p));
    }
    out
}

proptest! {
    /// Wherever the robot was switched on (its true odom frame) and
    /// whatever `odom_origin` says, in whatever frame the fixes come
    /// and with whatever latency: one fix (with heading) of the true
    /// pose at its stamp, carried by exact odometry, puts the world
    /// estimate on the truth now, and it stays there as the robot
    /// moves: exactly for an exact fix reset into the estimate, within
    /// 1 mm for a fix 0.1 mm sure fused by the EKF into an estimate the
    /// odometry's slip model made unsure.
    #[test]
    fn one_late_fix_puts_the_estimate_on_the_truth(
        true_origin in pose(), said_origin in pose(), frame in pose(), start in pose(),
        arcs in prop::collection::vec((-0.02..0.02f64, -0.05..0.05f64), 30..80),
        late in 0usize..14, ekf in any::<bool>(),
    ) {
        let truth = drive(start, &arcs);
        let (fix, model, tol) = if ekf {
            let errors = ErrorModel::PERFECT.with_slip(1e-2).unwrap();
            (spec(Fusion::Ekf, 1e-4, Some(1e-4)), OdometryModel { errors, ..MODEL }, 1e-3)
        } else {
            (spec(Fusion::Reset, 0.0, Some(0.0)), MODEL, 1e-6)
        };
        let mut f = input(
            source(FixMessage::PoseStamped, frame, false),
            fix,
            model,
            said_origin,
        );
        let raw = |p: &Pose| true_origin.between(p);
        let n = truth.len();
        for (i, (stamp, p)) in truth[..n - 10].iter().enumerate() {
            f.on_odom(*stamp, raw(p), i as f64 * 0.02);
        }
        // Fixes of the pose `late` samples ago (and one earlier), in
        // `frame`: the first is taken as it is, the second fused.
        for (ago, at) in [(late + 5, 0.9), (late, 1.0)] {
            let (stamp, then) = truth[n - 11 - ago];
            let seen = frame.between(&then);
            let msg = pose_msg(&seen, stamp, "map");
            prop_assert!(f.on_fix(&key(FixMessage::PoseStamped), &msg, at).is_ok());
        }
        for (i, (stamp, p)) in truth[n - 10..].iter().enumerate() {
            f.on_odom(*stamp, raw(p), 1.0 + i as f64 * 0.02);
            let est = f.correction().compose(&raw(p));
            prop_assert!((est.x - p.x).abs() < tol && (est.y - p.y).abs() < tol, "{est:?} vs {p:?}");
            prop_assert!(wrap_angle(est.theta - p.theta).abs() < tol);
        }
        prop_assert_eq!(f.counters().applied, 2);
    }
}

/// A stream of broken or implausible fixes: each one counted in its
/// own counter and refused, the correction unchanged; a good one after
/// them is applied.
#[test]
fn bad_fixes_are_counted_and_refused() {
    let origin = Pose {
        x: 1.0,
        y: 2.0,
        theta: 0.5,
    };
    let mut f = input(
        source(FixMessage::PoseStamped, Pose::default(), true),
        spec(Fusion::Reset, 0.005, None),
        MODEL,
        origin,
    );
    let k = key(FixMessage::PoseStamped);
    let here = origin;
    // No odometry yet: nothing to carry the fix by.
    assert_eq!(
        f.on_fix(&k, &pose_msg(&here, 0, "map"), 0.0),
        Err(FixRefusal::Unmatched)
    );
    f.on_odom(1_000, Pose::default(), 0.0);
    // The first fix is taken as it is.
    f.on_fix(&k, &pose_msg(&here, 1_000, "map"), 0.0)
        .expect("the first fix");
    let wrong_key = topic_key(KeyScheme::RmwZenoh, 0, TOPIC, &ODOMETRY);
    assert!(matches!(
        f.on_fix(&wrong_key, &pose_msg(&here, 1_000, "map"), 0.0),
        Err(FixRefusal::Sample(SampleRefusal::WrongType(_)))
    ));
    let mut truncated = pose_msg(&here, 1_000, "map");
    truncated.truncate(30);
    assert!(matches!(
        f.on_fix(&k, &truncated, 0.0),
        Err(FixRefusal::Sample(SampleRefusal::Malformed(_)))
    ));
    let nan = Pose {
        x: f64::NAN,
        ..here
    };
    assert!(matches!(
        f.on_fix(&k, &pose_msg(&nan, 1_000, "map"), 0.0),
        Err(FixRefusal::Sample(SampleRefusal::NonFinite(_)))
    ));
    assert!(matches!(
        f.on_fix(&k, &pose_msg(&here, 1_000, "odom"), 0.0),
        Err(FixRefusal::Frame(..))
    ));
    let mut zero_q = PoseStamped::planar(here.x, here.y, 0.0, Time::from_nanos(1_000), "map");
    zero_q.pose.orientation.w = 0.0;
    assert_eq!(
        f.on_fix(&k, &zero_q.to_cdr(), 0.0),
        Err(FixRefusal::Sample(SampleRefusal::Orientation))
    );
    // Not normalised beyond tf2's tolerance: |1.1² − 1| = 0.21.
    let mut long_q = PoseStamped::planar(here.x, here.y, 0.0, Time::from_nanos(1_000), "map");
    long_q.pose.orientation.w = 1.1;
    assert_eq!(
        f.on_fix(&k, &long_q.to_cdr(), 0.0),
        Err(FixRefusal::Sample(SampleRefusal::Orientation))
    );
    // 2 km away, beyond a 1 km guard (and the gate).
    let mut bounded = f
        .clone()
        .with_bounds(Bounds::new(100.0, 100.0, 1e3).unwrap());
    let beyond = Pose { x: 2e3, ..here };
    assert!(matches!(
        bounded.on_fix(&k, &pose_msg(&beyond, 1_000, "map"), 0.0),
        Err(FixRefusal::BeyondBounds { bound: 1e3, .. })
    ));
    assert_eq!(bounded.counters().beyond_bounds, 1);
    // 5 m away with 5 mm noise.
    let far = Pose {
        x: here.x + 5.0,
        ..here
    };
    assert!(matches!(
        f.on_fix(&k, &pose_msg(&far, 1_000, "map"), 0.0),
        Err(FixRefusal::Gated { .. })
    ));
    // Stamped before the history began.
    f.on_odom(2_000, Pose::default(), 0.02);
    assert_eq!(
        f.on_fix(&k, &pose_msg(&here, 500, "map"), 0.02),
        Err(FixRefusal::Unmatched)
    );
    assert_eq!(f.correction(), origin, "nothing refused moved the estimate");
    let c = *f.counters();
    assert_eq!(
        (
            c.received,
            c.unmatched,
            c.wrong_type,
            c.malformed,
            c.non_finite,
            c.wrong_frame,
            c.gated,
            c.applied
        ),
        (10, 2, 1, 3, 1, 1, 1, 1)
    );
    assert_eq!(c.beyond_bounds, 0);
    // 3 mm off: applied.
    let near = Pose {
        x: here.x + 0.003,
        ..here
    };
    f.on_fix(&k, &pose_msg(&near, 2_000, "map"), 0.02)
        .expect("a plausible fix");
    assert!((f.correction().x - near.x).abs() < 1e-12);
    assert_eq!(f.counters().applied, 2);
}

/// Fixes that all agree against the odometry (a robot carried away, or
/// odometry that drifted beyond the gate's belief) are believed after
/// [`RELOCALIZE_AFTER`] refusals in a row.
#[test]
fn consistent_refused_fixes_relocalise_the_robot() {
    let mut f = input(
        source(FixMessage::PoseStamped, Pose::default(), true),
        spec(Fusion::Ekf, 0.005, Some(0.01)),
        MODEL,
        Pose::default(),
    );
    let k = key(FixMessage::PoseStamped);
    let away = Pose {
        x: 3.0,
        y: -1.0,
        theta: 1.0,
    };
    f.on_odom(999, Pose::default(), 0.0);
    f.on_fix(&k, &pose_msg(&Pose::default(), 0, "map"), 0.0)
        .expect("the first fix");
    for i in 0..RELOCALIZE_AFTER {
        f.on_odom(1_000 + i64::from(i), Pose::default(), 0.1 * f64::from(i));
        let r = f.on_fix(&k, &pose_msg(&away, 0, "map"), 0.1 * f64::from(i));
        assert_eq!(r.is_ok(), i + 1 == RELOCALIZE_AFTER, "fix {i}: {r:?}");
    }
    let c = f.correction();
    assert!(
        (c.x - 3.0).abs() < 1e-12 && (c.y + 1.0).abs() < 1e-12 && (c.theta - 1.0).abs() < 1e-12
    );
    assert_eq!(f.counters().relocalized, 1);
    assert_eq!(f.counters().gated, u64::from(RELOCALIZE_AFTER));
    // The covariance is the fix's now.
    let p = f.covariance().expect("ekf");
    assert!((p[0][0] - 0.005f64.powi(2)).abs() < 1e-15);
}

/// AMCL's covariance is the fix's uncertainty: the same innovation
/// moves the EKF's estimate less the larger the message's covariance.
#[test]
fn a_pose_with_covariance_weighs_the_fix() {
    let shift = |var: f64| {
        let mut f = input(
            source(FixMessage::PoseWithCovarianceStamped, Pose::default(), true),
            spec(Fusion::Ekf, 0.0, None),
            OdometryModel {
                errors: ErrorModel::PERFECT.with_slip(1e-3).unwrap(),
                ..MODEL
            },
            Pose::default(),
        );
        let k = key(FixMessage::PoseWithCovarianceStamped);
        f.on_odom(999, Pose::default(), 0.0);
        let first = PoseWithCovarianceStamped::planar(
            0.0,
            0.0,
            0.0,
            [[var, 0.0, 0.0], [0.0, var, 0.0], [0.0, 0.0, 1e-6]],
            Time::default(),
            "map",
        );
        f.on_fix(&k, &first.to_cdr(), 0.0).expect("the first fix");
        // 1 m straight ahead grows the covariance.
        for i in 0..=100 {
            let p = Pose {
                x: 0.01 * f64::from(i),
                ..Pose::default()
            };
            f.on_odom(1_000 + i64::from(i), p, 0.02 * f64::from(i));
        }
        let cov = [[var, 0.0, 0.0], [0.0, var, 0.0], [0.0, 0.0, 0.0]];
        let msg = PoseWithCovarianceStamped::planar(1.0, 0.02, 0.0, cov, Time::default(), "map");
        f.on_fix(&k, &msg.to_cdr(), 2.0).expect("applied");
        let raw_now = Pose {
            x: 1.0,
            ..Pose::default()
        };
        f.correction().compose(&raw_now).y
    };
    let (sure, unsure) = (shift(1e-6), shift(1e-3));
    assert!(
        sure > unsure && unsure > 0.0 && sure < 0.02,
        "{sure} {unsure}"
    );
}

/// Theorem 2 in the loop: the requirement is `KinematicTheorem2`'s
/// inverse for the model's ζ at top speed; fixes spaced within it
/// raise nothing, one gap beyond it raises the flag (once); an outage
/// longer than the timeout is counted once and ends with the next fix.
#[test]
fn fix_intervals_are_held_against_theorem_2() {
    let model = OdometryModel {
        errors: ErrorModel::PERFECT
            .with_zeta(1e-4, echelon::odometry::ZetaModel::Wheels)
            .unwrap(),
        ..MODEL
    };
    let src = FixSource {
        tolerance: Some(0.05),
        ..source(FixMessage::PoseStamped, Pose::default(), false)
    };
    let mut f = input(src, spec(Fusion::Reset, 0.0, None), model, Pose::default());
    let req = f.report(0.0).required.expect("a requirement");
    let t2 = KinematicTheorem2::new(1.0, 1e-4, GAMMA).expect("valid");
    assert_eq!(req.steps, t2.max_steps(0.05).expect("steps"));
    assert!((req.interval - req.steps as f64 * 0.02).abs() < 1e-12);
    // ‖e‖ ≤ √2 N ζ/γ: N = ⌊0.05 · 0.99 / (√2 · 1e-4)⌋ = 350, 7 s.
    assert_eq!(req.steps, 350);
    let k = key(FixMessage::PoseStamped);
    let mut t = 0.0;
    let fix_at = |f: &mut FixInput, t: f64| {
        f.on_odom((t * 1e9) as i64 + 1, Pose::default(), t);
        f.on_fix(&k, &pose_msg(&Pose::default(), 0, "map"), t)
            .expect("applied");
    };
    for _ in 0..5 {
        fix_at(&mut f, t);
        t += 0.9 * req.interval;
    }
    assert!(!f.report(t).too_slow);
    t += 0.2 * req.interval;
    f.tick(t);
    // The default timeout: three fix periods of 0.1 s.
    assert_eq!(f.counters().outages, 1);
    f.tick(t + 1.0);
    assert_eq!(f.counters().outages, 1, "one report per outage");
    fix_at(&mut f, t);
    let rep = f.report(t);
    assert!(rep.too_slow);
    assert!((rep.interval_max.expect("intervals") - 1.1 * req.interval).abs() < 1e-9);
    assert_eq!(rep.age, Some(0.0));
}

/// A point `distance` m from the world origin in direction `angle`.
fn at_distance(distance: f64, angle: f64, theta: f64) -> Pose {
    Pose {
        x: distance * angle.cos(),
        y: distance * angle.sin(),
        theta,
    }
}

proptest! {
    /// The first fix is plausible or refused: one beyond the guard's
    /// position bound (any distance past it, up to 1e300 m) is refused
    /// and counted in `beyond_bounds`, and nothing changes (the
    /// correction, the covariance, no fix taken); a genuine first fix
    /// anywhere within the bound, however far from where `odom_origin`
    /// put the robot and however sure the odometry was, is taken as it is
    /// (relocalisation), gate or not; after it, a fix beyond the bound is
    /// refused the same way, gate or not (without the gate nothing else
    /// would refuse it).
    #[test]
    fn a_fix_beyond_the_bounds_is_refused_and_a_far_first_fix_within_them_taken(
        bound in 1.0..1e5f64,
        origin in pose(),
        inside in 0.0..1.0f64, inside_angle in -3.2..3.2f64, heading in -3.1..3.1f64,
        past in 1e-6..300.0f64, past_angle in -3.2..3.2f64,
        gate in any::<bool>(), ekf in any::<bool>(),
    ) {
        let (fusion, model) = if ekf {
            let errors = ErrorModel::PERFECT.with_slip(1e-4).unwrap();
            (Fusion::Ekf, OdometryModel { errors, ..MODEL })
        } else {
            (Fusion::Reset, MODEL)
        };
        let origin = Pose { x: origin.x.clamp(-bound, bound) / 2.0, y: origin.y.clamp(-bound, bound) / 2.0, ..origin };
        let mut f = input(
            source(FixMessage::PoseStamped, Pose::default(), gate),
            spec(fusion, 0.005, Some(0.01)),
            model,
            origin,
        )
        .with_bounds(Bounds::new(100.0, 100.0, bound).unwrap());
        let k = key(FixMessage::PoseStamped);
        for i in 0..20 {
            let raw = Pose { x: 0.01 * f64::from(i), ..Pose::default() };
            f.on_odom(1_000 + i64::from(i), raw, 0.02 * f64::from(i));
        }
        let raw_now = Pose { x: 0.19, ..Pose::default() };
        // Beyond: `bound · 10^past`, 1e-6 decades (a hair) to 300.
        let far = at_distance(bound * 10f64.powf(past), past_angle, heading);
        let fresh = f.clone();
        let r = f.on_fix(&k, &pose_msg(&far, 0, "map"), 0.4);
        prop_assert!(matches!(r, Err(FixRefusal::BeyondBounds { .. })), "{r:?}");
        prop_assert_eq!(f.counters().beyond_bounds, 1);
        prop_assert_eq!(f.counters().applied, 0);
        prop_assert_eq!(f.correction(), fresh.correction());
        prop_assert_eq!(f.covariance(), fresh.covariance());
        prop_assert!(f.last_fix().is_none());
        // Within, anywhere: taken as it is, the estimate now the fix.
        let near = at_distance(inside * bound, inside_angle, heading);
        prop_assert!(f.on_fix(&k, &pose_msg(&near, 0, "map"), 0.4).is_ok());
        let est = f.correction().compose(&raw_now);
        let tol = 1e-9 * bound.max(1.0);
        prop_assert!((est.x - near.x).abs() < tol && (est.y - near.y).abs() < tol, "{est:?} vs {near:?}");
        prop_assert!(wrap_angle(est.theta - near.theta).abs() < 1e-9);
        // Beyond again, after a fix: refused as beyond, nothing moved.
        let correction = f.correction();
        let r = f.on_fix(&k, &pose_msg(&far, 0, "map"), 0.5);
        prop_assert!(matches!(r, Err(FixRefusal::BeyondBounds { .. })), "{r:?}");
        prop_assert_eq!(f.correction(), correction);
        let c = f.counters();
        prop_assert_eq!((c.received, c.applied, c.beyond_bounds, c.gated), (3, 1, 2, 0));
    }
}

/// `for_agent` holds the fixes to the scenario's own `[sim] bounds`: with
/// `distance = 30`, a fix 40 m away is refused as beyond them, one 20 m
/// away (as far from `odom_origin`) taken.
#[test]
fn for_agent_bounds_the_fixes_by_the_scenarios_guard() {
    use echelon::scenario::{Overrides, Scenario};
    // The lab robots of the paper's experiment, taking fixes from ROS 2,
    // with a 30 m guard.
    let src = include_str!("../../../../../scenarios/experiment-circle-velocity.toml")
        .replace("[sim]\n", "[sim]\nbounds = { distance = 30.0 }\n")
        + "\n[odometry]\nperiod = 0.02\n\n[fixes]\nsource = \"/mocap/robot1/pose\"\nperiod = 0.1\nposition_noise = 0.005\n\n[fleet.ros2]\n";
    assert!(src.contains("bounds = { distance = 30.0 }"));
    let s = Scenario::parse(&src, "bounded.toml", None).unwrap_or_else(|e| panic!("{e}"));
    let plan = s
        .build(&Overrides::default())
        .unwrap_or_else(|e| panic!("{e}"))
        .plan;
    let link = s.fleet().unwrap_or_else(|e| panic!("{e}")).ros2[0].clone();
    let spec = crate::robot::agent_spec(&plan, 1).unwrap_or_else(|e| panic!("{e}"));
    let mut f = for_agent(1, &link, &plan, &spec)
        .unwrap_or_else(|e| panic!("{e}"))
        .expect("fixes");
    let k = key(FixMessage::PoseStamped);
    f.on_odom(1_000, Pose::default(), 0.0);
    let r = f.on_fix(&k, &pose_msg(&at_distance(40.0, 0.3, 0.0), 0, "map"), 0.0);
    assert!(
        matches!(r, Err(FixRefusal::BeyondBounds { distance, bound: 30.0 }) if (distance - 40.0).abs() < 1e-9),
        "{r:?}"
    );
    let near = at_distance(20.0, 0.3, 0.0);
    f.on_fix(&k, &pose_msg(&near, 0, "map"), 0.0)
        .expect("a first fix 20 m away, within the bounds");
    assert!((f.correction().x - near.x).abs() < 1e-12);
    assert_eq!((f.counters().applied, f.counters().beyond_bounds), (1, 1));
}
