#![allow(clippy::unwrap_used)]

use proptest::prelude::*;

use super::*;
use crate::law::control::{LeaderMotion, Offset};
use crate::law::kinematic::kinematic_law;
use crate::reference::Trajectory;

#[allow(clippy::type_complexity)]
fn buffers(env: &VecFormation) -> (Vec<f64>, Vec<f64>, Vec<f64>, Vec<f64>, Vec<EnvFacts>) {
    let c = env.config();
    let (e, n) = (c.num_envs, c.num_agents);
    (
        vec![0.0; e * n * 2],
        vec![0.0; e * n * env.obs_dim()],
        vec![0.0; e * n],
        vec![0.0; e * n],
        vec![EnvFacts::default(); e],
    )
}

/// Environment `k`'s robots sensed and placed again after a test moved
/// them by hand.
fn moved(env: &mut VecFormation, k: usize) {
    let (n, l) = (env.config.num_agents, env.config.l);
    let robots = &mut env.robots[k * n..(k + 1) * n];
    super::plant::sense(robots);
    super::plant::place(robots, l, &mut env.points[2 * n * k..2 * n * (k + 1)]);
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(32))]

    /// The observation's `e` and the baseline from it are the kernel's
    /// kinematic law at the same state (eq. 7, eq. 10's `ξ*`): the
    /// layout carries what the law needs, nothing is lost.
    #[test]
    fn the_baseline_from_observations_is_the_kinematic_law(
        n in 1usize..9, k in 0usize..6, seed in any::<u64>(), ke in 0.2..3.0f64,
        jitter in proptest::collection::vec((-0.5..0.5f64, -0.5..0.5f64, -3.0..3.0f64, -0.4..0.4f64, -1.5..1.5f64), 8),
    ) {
        let mut config = EnvConfig::new(2, n);
        config.neighbours = k;
        let mut env = VecFormation::new(config, seed).unwrap();
        // Move the robots off their starts and give them speeds.
        let n_ = n;
        for (i, r) in env.robots[n_..2 * n_].iter_mut().enumerate() {
            let s = &mut r.state;
            let (dx, dy, th, v, w) = jitter[i];
            s.x += dx; s.y += dy; s.theta = th; s.v = v; s.omega = w;
        }
        env.envs[1].t = 0.7;
        moved(&mut env, 1);
        let d = env.obs_dim();
        let mut obs = vec![0.0; 2 * n * d];
        env.observe(&mut obs);
        let mut actions = vec![0.0; 2 * n * 2];
        baseline(&obs, d, ke, &mut actions);
        let slots: Vec<[f64; 2]> = env.slots(1).collect();
        let jet = env.leader(1).eval(0.7, crate::reference::Order::Two);
        let leader = LeaderMotion::of_jet(&jet);
        for i in 0..n {
            let off = Offset { lx: slots[i][0], ly: slots[i][1], dly: 0.0, ddly: 0.0 };
            let law = kinematic_law(&env.robots[n + i].state, &leader, &off, ke);
            let o = &obs[(n + i) * d..(n + i + 1) * d];
            let a = &actions[(n + i) * 2..(n + i + 1) * 2];
            prop_assert!((o[0] - law.e[0]).abs() < 1e-12 && (o[1] - law.e[1]).abs() < 1e-12, "{o:?} {law:?}");
            prop_assert!((a[0] - law.cmd.v).abs() < 1e-9 * (1.0 + law.cmd.v.abs()), "{a:?} {law:?}");
            prop_assert!((a[1] - law.cmd.omega).abs() < 1e-9 * (1.0 + law.cmd.omega.abs()), "{a:?} {law:?}");
            // Neighbours: listed ones within `sense`, nearest first, padding zero.
            let mut last = 0.0;
            for m in 0..k {
                let nb = &o[10 + 3 * m..13 + 3 * m];
                if nb[2] == 1.0 {
                    let dist = nb[0].hypot(nb[1]);
                    prop_assert!(dist >= last - 1e-12 && dist <= config.sense);
                    last = dist;
                } else {
                    prop_assert!(nb == [0.0; 3]);
                }
            }
            let listed = (0..k).filter(|m| o[12 + 3 * m] == 1.0).count();
            let me = crate::safety::point(&env.robots[n + i].state, config.l);
            let within = env.robots[n..2 * n].iter().enumerate().filter(|&(j, r)| {
                let p = crate::safety::point(&r.state, config.l);
                j != i && (p[0] - me[0]).hypot(p[1] - me[1]) <= config.sense
            }).count();
            prop_assert_eq!(listed, k.min(within));
        }
    }

    /// Under the baseline, every robot of every environment reaches its
    /// slot: ‖e‖ below 1 cm after 40 s, whatever the draw (leader speed up
    /// to 0.2 m/s, turn rate up to 0.1 rad/s, starts up to 0.2 spacings off
    /// and 0.5 rad turned).
    #[test]
    fn the_baseline_brings_everyone_to_their_slots(n in 1usize..10, seed in any::<u64>(), spacing in 0.8..3.0f64) {
        let mut config = EnvConfig::new(3, n);
        config.spacing = spacing;
        config.max_steps = 100_000;
        let mut env = VecFormation::new(config, seed).unwrap();
        let (mut actions, mut obs, mut rewards, mut changed, mut facts) = buffers(&env);
        let d = env.obs_dim();
        env.observe(&mut obs);
        for _ in 0..800 {
            baseline(&obs, d, 1.0, &mut actions);
            env.step(&actions, &mut obs, &mut rewards, &mut changed, &mut facts);
        }
        for (i, o) in obs.chunks_exact(d).enumerate() {
            prop_assert!(o[0].hypot(o[1]) < 0.01, "robot {i}: e = ({}, {})", o[0], o[1]);
        }
        // The rewards are the documented formula of what was observed:
        // −‖e‖² − 0.01 ‖(v, Lω)‖² − 10 [nearest point within the radius].
        for (i, o) in obs.chunks_exact(d).enumerate() {
            let (v, w) = (actions[2 * i].clamp(-0.5, 0.5), actions[2 * i + 1].clamp(-2.0, 2.0));
            let hit = o[12] == 1.0 && o[10].hypot(o[11]) < config.radius;
            let want = -(o[0] * o[0] + o[1] * o[1])
                - 0.01 * (v * v + (config.l * w).powi(2))
                - if hit { 10.0 } else { 0.0 };
            prop_assert!((rewards[i] - want).abs() < 1e-12, "robot {i}: {} vs {want}", rewards[i]);
        }
    }

    /// With the filter, random actions in a crowd never bring two points
    /// closer than the radius (less 1 mm); the same actions without it do
    /// (the test is not vacuous).
    #[test]
    fn the_filter_keeps_the_radius_under_random_actions(seed in any::<u64>(), n in 4usize..9) {
        let mut config = EnvConfig::new(4, n);
        config.spacing = 0.5;
        config.radius = 0.3;
        let mut rng = crate::math::rng::SplitMix64::new(seed);
        let mut closest = [f64::INFINITY; 2];
        for (pass, safety) in [true, false].into_iter().enumerate() {
            config.safety = safety;
            let mut env = VecFormation::new(config, seed).unwrap();
            let (mut actions, mut obs, mut rewards, mut changed, mut facts) = buffers(&env);
            let mut draws = crate::math::rng::SplitMix64::new(seed ^ 1);
            for _ in 0..300 {
                for a in actions.chunks_exact_mut(2) {
                    a[0] = draws.uniform(-0.5, 0.5);
                    a[1] = draws.uniform(-2.0, 2.0);
                }
                env.step(&actions, &mut obs, &mut rewards, &mut changed, &mut facts);
                for f in &facts {
                    closest[pass] = closest[pass].min(f.min_distance);
                }
            }
            let _ = rng.next_u64();
        }
        prop_assert!(closest[0] >= config.radius - 1e-3, "with the filter: {}", closest[0]);
        prop_assert!(closest[1] < config.radius, "without it: {}", closest[1]);
    }
}

/// A reset with a mask changes the selected environments only; the same
/// seed gives the same episodes, another seed others.
#[test]
fn a_masked_reset_leaves_the_others_untouched() {
    let config = EnvConfig::new(5, 3);
    let mut a = VecFormation::new(config, 7).unwrap();
    let b = VecFormation::new(config, 7).unwrap();
    let c = VecFormation::new(config, 8).unwrap();
    let states = |v: &VecFormation| v.states().copied().collect::<Vec<_>>();
    assert_eq!(states(&a), states(&b));
    assert_ne!(states(&a), states(&c));
    let (mut actions, mut obs, mut rewards, mut changed, mut facts) = buffers(&a);
    actions.fill(0.3);
    a.step(&actions, &mut obs, &mut rewards, &mut changed, &mut facts);
    let before = states(&a);
    a.reset(9, Some(&[false, true, false, false, true]));
    let after = states(&a);
    for k in 0..5 {
        let same = before[3 * k..3 * k + 3] == after[3 * k..3 * k + 3];
        assert_eq!(same, ![1, 4].contains(&k), "env {k}");
    }
    assert!(a.time(0) > 0.0 && a.time(1) == 0.0);
    // Environments draw different episodes from one seed.
    assert_ne!(
        a.slots(0).collect::<Vec<_>>(),
        a.slots(2).collect::<Vec<_>>()
    );
    assert!((a.leader(0).eval(0.0, crate::reference::Order::Two).p[0]).abs() < 1e-12);
}

/// Truncation comes at `max_steps`, actions are clipped to the base's
/// limits, and a bad configuration is refused.
#[test]
fn truncation_clipping_and_refusals() {
    let mut config = EnvConfig::new(1, 2);
    config.max_steps = 3;
    let mut env = VecFormation::new(config, 1).unwrap();
    let (mut actions, mut obs, mut rewards, mut changed, mut facts) = buffers(&env);
    actions.copy_from_slice(&[9.0, -9.0, -9.0, 9.0]);
    for step in 1..=3 {
        env.step(&actions, &mut obs, &mut rewards, &mut changed, &mut facts);
        assert_eq!(facts[0].truncated, step == 3);
    }
    let d = env.obs_dim();
    assert!((obs[2] - 0.5).abs() < 1e-12 && (obs[3] + 2.0).abs() < 1e-12);
    assert!((obs[d + 2] + 0.5).abs() < 1e-12 && (obs[d + 3] - 2.0).abs() < 1e-12);
    for bad in [
        EnvConfig {
            num_envs: 0,
            ..config
        },
        EnvConfig { dt: 0.0, ..config },
        EnvConfig {
            neighbours: 17,
            ..config
        },
        EnvConfig {
            seen_obstacles: 17,
            ..config
        },
        EnvConfig {
            obstacle_radius: (0.0, 0.2),
            ..config
        },
        EnvConfig {
            obstacle_radius: (0.3, 0.2),
            ..config
        },
        EnvConfig {
            speed: (0.3, 0.1),
            ..config
        },
        EnvConfig {
            base: crate::model::base::VelocityBase::IDEAL,
            ..config
        },
    ] {
        assert!(VecFormation::new(bad, 1).is_err(), "{bad:?}");
    }
    assert_eq!(first_not_finite(&[0.0, 1.0, f64::NAN]), Some(2));
    assert_eq!(first_not_finite(&[0.0f32, 1.0]), None);
}

/// Table I's agent 1 with a 10 N m wheel limit.
fn torque_config(e: usize, n: usize) -> EnvConfig {
    EnvConfig {
        robot: Some(
            crate::model::RobotParams::AGENT1
                .with_torque_limit(Some(10.0))
                .unwrap(),
        ),
        dt: 0.01,
        ..EnvConfig::new(e, n)
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(16))]

    /// On torque-driven robots the observation carries what the complete
    /// law needs: the baseline from observations is the kernel's law at the
    /// robot's true pose (the law does not depend on the frame) to 1e-9,
    /// as wheel torques.
    #[test]
    fn the_torque_baseline_from_observations_is_the_complete_law(
        n in 1usize..6, seed in any::<u64>(),
        jitter in proptest::collection::vec((-0.4..0.4f64, -0.4..0.4f64, -3.0..3.0f64, -0.4..0.4f64, -1.5..1.5f64), 6),
    ) {
        let config = torque_config(1, n);
        let robot = config.robot.unwrap();
        let mut env = VecFormation::new(config, seed).unwrap();
        for (i, r) in env.robots[..n].iter_mut().enumerate() {
            let s = &mut r.state;
            let (dx, dy, th, v, w) = jitter[i];
            s.x += dx; s.y += dy; s.theta = th; s.v = v; s.omega = w;
        }
        env.envs[0].t = 1.3;
        moved(&mut env, 0);
        let d = env.obs_dim();
        let mut obs = vec![0.0; n * d];
        env.observe(&mut obs);
        let mut actions = vec![0.0; n * 2];
        let gains = crate::law::control::Gains::PAPER;
        baseline_torque(&obs, d, &robot, gains, &mut actions);
        let slots: Vec<[f64; 2]> = env.slots(0).collect();
        let leader = LeaderMotion::of_jet(&env.leader(0).eval(1.3, crate::reference::Order::Two));
        for i in 0..n {
            let off = Offset { lx: slots[i][0], ly: slots[i][1], dly: 0.0, ddly: 0.0 };
            let u = crate::law::control::law(&robot, &env.robots[i].state, &leader, &off, gains, crate::law::control::Variant::Complete).u;
            let tau = robot.torques(u);
            let a = &actions[2 * i..2 * i + 2];
            prop_assert!((a[0] - tau.right).abs() < 1e-9 * (1.0 + tau.right.abs()), "{a:?} {tau:?}");
            prop_assert!((a[1] - tau.left).abs() < 1e-9 * (1.0 + tau.left.abs()), "{a:?} {tau:?}");
        }
    }

    /// Torque-driven robots under the baseline reach their slots (‖e‖ < 1 cm
    /// after 30 s), and the filter keeps the radius under random torques in
    /// a crowd.
    #[test]
    fn torque_robots_get_home_and_keep_the_radius(n in 1usize..7, seed in any::<u64>()) {
        let config = torque_config(2, n);
        let robot = config.robot.unwrap();
        let mut env = VecFormation::new(config, seed).unwrap();
        let (mut actions, mut obs, mut rewards, mut changed, mut facts) = buffers(&env);
        let d = env.obs_dim();
        env.observe(&mut obs);
        for _ in 0..3000 {
            baseline_torque(&obs, d, &robot, crate::law::control::Gains::PAPER, &mut actions);
            env.step(&actions, &mut obs, &mut rewards, &mut changed, &mut facts);
        }
        for (i, o) in obs.chunks_exact(d).enumerate() {
            prop_assert!(o[0].hypot(o[1]) < 0.01, "robot {i}: e = ({}, {})", o[0], o[1]);
        }
        let crowd = EnvConfig { spacing: 0.5, radius: 0.3, safety: true, ..torque_config(2, n.max(3)) };
        let mut env = VecFormation::new(crowd, seed).unwrap();
        let (mut actions, mut obs, mut rewards, mut changed, mut facts) = buffers(&env);
        let mut draws = crate::math::rng::SplitMix64::new(seed);
        let mut closest = f64::INFINITY;
        for _ in 0..500 {
            for a in &mut actions {
                *a = draws.uniform(-10.0, 10.0);
            }
            env.step(&actions, &mut obs, &mut rewards, &mut changed, &mut facts);
            closest = facts.iter().map(|f| f.min_distance).fold(closest, f64::min);
        }
        prop_assert!(closest >= 0.3 - 1e-3, "closest {closest}");
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]

    /// The step in lanes across environments ([`plant`]) is the base model
    /// robot by robot: each state after a step is
    /// [`VelocityBase::rk4_step`] under the clipped, limited action to
    /// 1e-12 (the polynomial sines and cosines are within a few ulp of the
    /// platform's), on bases with and without lags and acceleration limits,
    /// whatever the grouping of robots into lanes and environments; the
    /// headings' sines and cosines and the points are the state's.
    #[test]
    fn the_step_in_lanes_is_the_base_model_robot_by_robot(
        e in 1usize..6, n in 1usize..13, seed in any::<u64>(),
        tau in (prop_oneof![Just(0.0), 0.02..0.5f64], prop_oneof![Just(0.0), 0.02..0.5f64]),
        acc in (prop_oneof![Just(f64::INFINITY), 0.2..3.0f64], prop_oneof![Just(f64::INFINITY), 0.5..6.0f64]),
        joint in any::<bool>(), limits in (0.1..1.5f64, 0.3..4.0f64),
        raw in proptest::collection::vec(-3.0..3.0f64, 2 * 5 * 12 * 6),
    ) {
        use crate::model::base::{AccelLimit, VelocityBaseSpec, VelocityCommand};
        let base = VelocityBase::new(VelocityBaseSpec {
            tau_v: tau.0, tau_omega: tau.1, v_max: limits.0, omega_max: limits.1,
            // An axis without lag has no acceleration to limit.
            a_max: if tau.0 > 0.0 { acc.0 } else { f64::INFINITY },
            alpha_max: if tau.1 > 0.0 { acc.1 } else { f64::INFINITY },
            accel: if joint { AccelLimit::Joint } else { AccelLimit::PerAxis },
        }).unwrap();
        let config = EnvConfig { base, dt: 0.02, ..EnvConfig::new(e, n) };
        let mut env = VecFormation::new(config, seed).unwrap();
        let (mut actions, mut obs, mut rewards, mut changed, mut facts) = buffers(&env);
        for step in 0..5 {
            let per = 2 * e * n;
            actions.copy_from_slice(&raw[step * per..(step + 1) * per]);
            let before: Vec<State> = env.states().copied().collect();
            env.step(&actions, &mut obs, &mut rewards, &mut changed, &mut facts);
            for (r, (s, was)) in env.states().zip(&before).enumerate() {
                let a = [actions[2 * r].clamp(-limits.0, limits.0), actions[2 * r + 1].clamp(-limits.1, limits.1)];
                let cmd = base.limit(VelocityCommand { v: a[0], omega: a[1] }).0;
                let want = base.rk4_step(was, cmd, config.dt);
                for (got, want) in [(s.x, want.x), (s.y, want.y), (s.theta, want.theta), (s.v, want.v), (s.omega, want.omega)] {
                    prop_assert!((got - want).abs() <= 1e-12 * (1.0 + want.abs()), "robot {r} step {step}: {s:?} vs {want:?}");
                }
            }
            for (g, r) in env.robots.iter().enumerate() {
                let (k, i) = (g / n, g % n);
                let (s, h) = (&r.state, r.heading);
                let p = [env.points[2 * n * k + i], env.points[2 * n * k + n + i]];
                {
                    let (sin, cos) = s.theta.sin_cos();
                    let q = crate::safety::point(s, config.l);
                    prop_assert!((h[0] - sin).abs() < 1e-15 && (h[1] - cos).abs() < 1e-15, "{h:?} vs {sin}, {cos}");
                    prop_assert!((p[0] - q[0]).abs() < 1e-14 && (p[1] - q[1]).abs() < 1e-14, "{p:?} vs {q:?}");
                }
            }
        }
    }

    /// Each observation is its robot's world seen from its frame, computed
    /// here one robot at a time with the platform's `sin_cos` and the
    /// leader's own `eval`: the tracking error (eq. 7), the leader's
    /// velocity and acceleration, and the `K` nearest points within `sense`
    /// (ties to the lower index) by a brute-force sort; the facts' closest
    /// distance is the smallest pair's. Over several environments, so that
    /// groups of them (and leaders evaluated together in lanes) are met.
    #[test]
    fn the_observations_are_each_robots_world_by_brute_force(
        e in 1usize..24, n in 1usize..40, k in 0usize..17, seed in any::<u64>(), sense in 0.2..6.0f64,
        spacing in 0.2..2.0f64, steps in 1usize..4, m in 0usize..10, ko in 0usize..17,
        size in 0.02..1.0f64,
    ) {
        let config = EnvConfig {
            neighbours: k, sense, spacing, turn: 1.0, obstacles: m, seen_obstacles: ko,
            obstacle_radius: (size, 2.0 * size), ..EnvConfig::new(e, n)
        };
        let mut env = VecFormation::new(config, seed).unwrap();
        let (mut actions, mut obs, mut rewards, mut changed, mut facts) = buffers(&env);
        for (i, a) in actions.iter_mut().enumerate() {
            *a = 0.3 * ((i as f64) * 0.77).sin();
        }
        for _ in 0..steps {
            env.step(&actions, &mut obs, &mut rewards, &mut changed, &mut facts);
        }
        let d = env.obs_dim();
        for env_k in 0..e {
            let states: Vec<State> = env.states().skip(env_k * n).take(n).copied().collect();
            let slots: Vec<[f64; 2]> = env.slots(env_k).collect();
            let jet = env.leader(env_k).eval(env.time(env_k), crate::reference::Order::Two);
            let points: Vec<[f64; 2]> = states.iter().map(|s| crate::safety::point(s, config.l)).collect();
            let obstacles = env.obstacles(env_k);
            prop_assert_eq!(obstacles.len(), m);
            let mut closest = f64::INFINITY;
            let mut clearance = f64::INFINITY;
            let mut mean = 0.0;
            for (i, me) in points.iter().enumerate() {
                let mut others: Vec<(f64, usize)> = points.iter().enumerate().filter(|&(j, _)| j != i)
                    .map(|(j, p)| ((p[0] - me[0]).powi(2) + (p[1] - me[1]).powi(2), j)).collect();
                others.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
                closest = others.first().map_or(closest, |o| closest.min(o.0.sqrt()));
                let listed: Vec<usize> = others.iter().filter(|o| o.0 <= sense * sense).take(k).map(|o| o.1).collect();
                let o = &obs[(env_k * n + i) * d..(env_k * n + i + 1) * d];
                let s = &states[i];
                let (sin, cos) = s.theta.sin_cos();
                let frame = |v: [f64; 2]| [cos * v[0] + sin * v[1], -sin * v[0] + cos * v[1]];
                let err = frame([s.x - jet.p[0], s.y - jet.p[1]]);
                let want_head = [
                    err[0] + slots[i][0], err[1] + slots[i][1], s.v, s.omega,
                    frame(jet.dp)[0], frame(jet.dp)[1], frame(jet.ddp)[0], frame(jet.ddp)[1],
                    slots[i][0], slots[i][1],
                ];
                for (m, (got, want)) in o[..10].iter().zip(want_head).enumerate() {
                    prop_assert!((got - want).abs() < 1e-12 * (1.0 + want.abs()), "env {env_k} robot {i} value {m}: {got} vs {want}");
                }
                for m in 0..k {
                    let nb = &o[10 + 3 * m..13 + 3 * m];
                    match listed.get(m) {
                        Some(&j) => {
                            let want = frame([points[j][0] - me[0], points[j][1] - me[1]]);
                            prop_assert!(nb[2] == 1.0 && (nb[0] - want[0]).abs() < 1e-12 && (nb[1] - want[1]).abs() < 1e-12,
                                "env {env_k} robot {i} slot {m}: {nb:?}, want {want:?} (robot {j})");
                        }
                        None => prop_assert!(nb == [0.0; 3], "env {env_k} robot {i} slot {m}: {nb:?}"),
                    }
                }
                let mut edges: Vec<(f64, usize)> = obstacles.iter().enumerate()
                    .map(|(j, c)| ((c.x() - me[0]).hypot(c.y() - me[1]) - c.r(), j)).collect();
                edges.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
                let edge = edges.first().map_or(f64::INFINITY, |x| x.0);
                clearance = clearance.min(edge);
                let seen: Vec<usize> = edges.iter().filter(|x| x.0 <= sense).take(ko).map(|x| x.1).collect();
                let at = 10 + 3 * k;
                for slot in 0..ko {
                    let ob = &o[at + 4 * slot..at + 4 * slot + 4];
                    match seen.get(slot) {
                        Some(&j) => {
                            let c = &obstacles[j];
                            let want = frame([c.x() - me[0], c.y() - me[1]]);
                            prop_assert!(ob[3] == 1.0 && ob[2] == c.r() && (ob[0] - want[0]).abs() < 1e-12 && (ob[1] - want[1]).abs() < 1e-12,
                                "env {env_k} robot {i} obstacle slot {slot}: {ob:?}, want {want:?} (obstacle {j})");
                        }
                        None => prop_assert!(ob == [0.0; 4], "env {env_k} robot {i} obstacle slot {slot}: {ob:?}"),
                    }
                }
                // The reward of the step that ended: the action applied
                // (within the limits: unclipped), the collisions counted.
                let a = &actions[(env_k * n + i) * 2..(env_k * n + i) * 2 + 2];
                let w = config.weights;
                let near = others.first().map_or(f64::INFINITY, |o| o.0.sqrt());
                let hits = f64::from(u8::from(near < config.radius) + u8::from(edge < config.radius));
                let want = -w.tracking * (err[0] + slots[i][0]).hypot(err[1] + slots[i][1]).powi(2)
                    - w.effort * (a[0] * a[0] + (config.l * a[1]).powi(2)) - w.collision * hits;
                let got = rewards[env_k * n + i];
                prop_assert!((got - want).abs() < 1e-9 * (1.0 + want.abs()), "env {env_k} robot {i} reward {got} vs {want}");
                mean += want / n as f64;
            }
            prop_assert!((facts[env_k].reward - mean).abs() < 1e-9 * (1.0 + mean.abs()));
            let got = facts[env_k].obstacle_distance;
            prop_assert!((got - clearance).abs() < 1e-12 || clearance.is_infinite() && got.is_infinite(), "env {env_k}: {got} vs {clearance}");
            let got = facts[env_k].min_distance;
            prop_assert!((got - closest).abs() < 1e-12 || closest.is_infinite() && got.is_infinite(), "env {env_k}: {got} vs {closest}");
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]

    /// A drawn episode's obstacles: as many as asked, radii in their range,
    /// every edge at least the radius from every robot's start point, each
    /// on the leader's path (within the formation's half-width and a
    /// spacing of a place the leader passes in the episode) or, when the
    /// draw found no clear place there, ahead of every robot; and the
    /// leader, slots and starts are those of the same episode without
    /// obstacles.
    #[test]
    fn obstacles_are_drawn_on_the_path_clear_of_the_starts(
        e in 1usize..4, n in 1usize..30, m in 1usize..12, seed in any::<u64>(),
        spacing in 0.2..2.5f64, radius in 0.05..1.0f64, size in 0.02..1.5f64, turn in 0.0..1.0f64,
        max_steps in 1u64..800,
    ) {
        let plain = EnvConfig { spacing, radius, turn, max_steps, ..EnvConfig::new(e, n) };
        let config = EnvConfig { obstacles: m, obstacle_radius: (size, 1.5 * size), ..plain };
        let (with, without) = (VecFormation::new(config, seed).unwrap(), VecFormation::new(plain, seed).unwrap());
        let starts: Vec<State> = with.states().copied().collect();
        prop_assert_eq!(&starts, &without.states().copied().collect::<Vec<_>>());
        let horizon = max_steps as f64 * config.dt;
        let half = 0.5 * ((n as f64).sqrt().ceil() - 1.0) * spacing + 1.15 * spacing;
        for k in 0..e {
            prop_assert_eq!(with.slots(k).collect::<Vec<_>>(), without.slots(k).collect::<Vec<_>>());
            let jet = |f: &VecFormation| f.leader(k).eval(1.0, crate::reference::Order::Two);
            prop_assert_eq!(jet(&with), jet(&without));
            prop_assert!(without.obstacles(k).is_empty());
            let obstacles = with.obstacles(k);
            prop_assert_eq!(obstacles.len(), m);
            let points: Vec<[f64; 2]> =
                starts[k * n..(k + 1) * n].iter().map(|s| crate::safety::point(s, config.l)).collect();
            let far = points.iter().fold(0.0f64, |f, p| f.max(p[0].hypot(p[1])));
            let path: Vec<[f64; 2]> = (0..=2000)
                .map(|i| with.leader(k).eval(horizon * i as f64 / 2000.0, crate::reference::Order::Two).p)
                .collect();
            let step = path.windows(2).fold(0.0f64, |s, w| s.max((w[1][0] - w[0][0]).hypot(w[1][1] - w[0][1])));
            for o in obstacles {
                prop_assert!(size <= o.r() && o.r() <= 1.5 * size, "radius {}", o.r());
                for p in &points {
                    let edge = (p[0] - o.x()).hypot(p[1] - o.y()) - o.r();
                    prop_assert!(edge >= radius - 1e-12, "an edge {edge} from a start point, radius {radius}");
                }
                let off = path.iter().fold(f64::INFINITY, |d, p| d.min((p[0] - o.x()).hypot(p[1] - o.y())));
                let ahead = o.x().hypot(o.y()) >= far + o.r() + radius;
                prop_assert!(off <= half + step + 1e-9 || ahead, "{o:?}: {off} off the path (half-width {half})");
            }
        }
    }

    /// With the filter the baseline (with noise) through a crowd on a path
    /// strewn with obstacles keeps every point the radius clear of every
    /// edge (less 1 mm); without it the same formation runs into them (the
    /// test is not vacuous). Two robots squeezed between obstacles may
    /// come up to 1 cm inside the radius of each other at these 50 ms
    /// steps (7 mm seen; docs/safety.md, "Open"): their shares of the pair
    /// cannot all be taken without moving into an obstacle, which the
    /// filter never does ([`crate::safety::SafetyFilter::velocity`]).
    /// Without obstacles the radius holds to 1 mm
    /// (`the_filter_keeps_the_radius_under_random_actions`).
    #[test]
    fn the_filter_keeps_the_obstacles_clear(seed in any::<u64>(), n in 2usize..8, m in 4usize..10) {
        let mut config = EnvConfig {
            spacing: 0.6, radius: 0.25, obstacles: m, obstacle_radius: (0.15, 0.4),
            speed: (0.15, 0.2), max_steps: 300, seen_obstacles: 2, ..EnvConfig::new(4, n)
        };
        let mut clearance = [f64::INFINITY; 2];
        let mut closest = f64::INFINITY;
        for (pass, safety) in [true, false].into_iter().enumerate() {
            config.safety = safety;
            let mut env = VecFormation::new(config, seed).unwrap();
            let (mut actions, mut obs, mut rewards, mut changed, mut facts) = buffers(&env);
            env.observe(&mut obs);
            let mut draws = crate::math::rng::SplitMix64::new(seed ^ 1);
            for _ in 0..config.max_steps {
                baseline(&obs, env.obs_dim(), 1.0, &mut actions);
                for a in actions.chunks_exact_mut(2) {
                    a[0] += draws.uniform(-0.1, 0.1);
                    a[1] += draws.uniform(-0.5, 0.5);
                }
                env.step(&actions, &mut obs, &mut rewards, &mut changed, &mut facts);
                for f in &facts {
                    clearance[pass] = clearance[pass].min(f.obstacle_distance);
                    if safety {
                        closest = closest.min(f.min_distance);
                    }
                }
            }
        }
        prop_assert!(clearance[0] >= config.radius - 1e-3, "with the filter: {}", clearance[0]);
        prop_assert!(closest >= config.radius - 1e-2, "with the filter, between robots: {closest}");
        prop_assert!(clearance[1] < config.radius, "without it: {}", clearance[1]);
    }
}

/// A scenario's obstacles are every episode's; drawn obstacles are refused
/// beside them.
#[test]
fn a_scenarios_obstacles_are_its_episodes() {
    let leader = Reference::Circle(crate::reference::Circle::new([0.0; 2], 0.0, 0.1, 0.0).unwrap());
    let obstacles = vec![
        crate::safety::Obstacle::new(2.0, 0.5, 0.3).unwrap(),
        crate::safety::Obstacle::new(1.5, -0.5, 0.2).unwrap(),
    ];
    let fixed = FixedEpisode {
        leader,
        lx: vec![1.0, 1.0],
        ly: vec![0.5, -0.5],
        starts: vec![
            State::at_rest(-1.0, -0.5, 0.0),
            State::at_rest(-1.0, 0.5, 0.0),
        ],
        obstacles: obstacles.clone(),
    };
    let config = EnvConfig {
        seen_obstacles: 3,
        ..EnvConfig::new(3, 2)
    };
    let mut env = VecFormation::fixed(config, fixed.clone(), 5).unwrap();
    assert_eq!(env.config().obstacles, 2);
    for k in 0..3 {
        assert_eq!(env.obstacles(k), &obstacles[..]);
    }
    env.reset_next(&[true, false, true]);
    assert_eq!(env.obstacles(2), &obstacles[..]);
    let mut obs = vec![0.0f64; 3 * 2 * env.obs_dim()];
    env.observe(&mut obs);
    // Robot 0 at (−1, −0.5) facing x, its point 0.1 ahead: the second
    // obstacle's edge 2.2 m away, the first's 2.77 m (within `sense`, 3 m),
    // then padding.
    let at = layout::obstacles(config.neighbours);
    let want = [2.4, 0.0, 0.2, 1.0, 2.9, 1.0, 0.3, 1.0, 0.0, 0.0, 0.0, 0.0];
    for (got, want) in obs[at..at + 12].iter().zip(want) {
        assert!((got - want).abs() < 1e-12, "{:?}", &obs[at..at + 12]);
    }
    let drawn = EnvConfig {
        obstacles: 1,
        ..config
    };
    assert!(VecFormation::fixed(drawn, fixed, 5).is_err());
}
