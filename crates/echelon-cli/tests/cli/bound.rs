//! `echelon bound`: forward and inverse agree, the kinematic law, refusals.

use super::*;

#[test]
fn bound_forward_and_inverse_agree() {
    let common = [
        "bound",
        "--ke",
        "1.5",
        "--kz",
        "10",
        "--zeta",
        "1e-4",
        "--omega-max",
        "1",
        "--gamma",
        "0.5",
    ];
    let forward = json(&echelon(
        &[&common[..], &["--steps", "1000", "--ts", "0.01", "--json"]].concat(),
    ));
    let z = forward["z_bound"].as_f64().unwrap();
    let want = 2f64.sqrt() * 1.5 * 1000.0 * 1e-4 * 101f64.sqrt() / (10.0 * 0.5);
    assert!((z - want).abs() < 1e-12 * want, "{forward}");
    assert_eq!(forward["steps"], 1000);
    assert!((forward["fix_period_s"].as_f64().unwrap() - 10.0).abs() < 1e-9);
    // The inverse of that bound is N = 1000 again, and N + 1 would exceed it.
    let z_text = format!("{z:e}");
    let inverse = json(&echelon(
        &[&common[..], &["--max-z", &z_text, "--ts", "0.01", "--json"]].concat(),
    ));
    assert_eq!(inverse["steps"], 1000, "{inverse}");
    let inverse = json(&echelon(
        &[&common[..], &["--max-z", "0.05", "--json"]].concat(),
    ));
    let n = inverse["steps"].as_u64().unwrap();
    assert!(n as f64 * want / 1000.0 <= 0.05 && (n + 1) as f64 * want / 1000.0 > 0.05);
    assert!(inverse["fix_period_s"].is_null());
    // --max-e: ‖e‖ ≤ ‖z‖/K_e.
    let by_e = json(&echelon(
        &[&common[..], &["--max-e", "0.02", "--json"]].concat(),
    ));
    assert_eq!(
        by_e["steps"],
        json(&echelon(
            &[&common[..], &["--max-z", "0.03", "--json"]].concat()
        ))["steps"]
    );
    let text = stdout(&echelon(
        &[&common[..], &["--max-z", "0.05", "--ts", "0.01"]].concat(),
    ));
    assert!(
        text.contains(&format!("N = {n} samples")) && text.contains("fix at least every"),
        "{text}"
    );
}

/// `--law kinematic`: `‖e‖ ≤ √2 N ζ / γ` both ways, the largest `N` its
/// own inverse, over a grid of inputs; `--max-z` and a dynamic bound
/// without `--omega-max` are refused.
#[test]
fn bound_for_the_kinematic_law() {
    for (ke, zeta, gamma, max_e) in [
        ("1.0", "1e-4", "0.99", "0.05"),
        ("2.5", "3e-6", "0.5", "0.02"),
        ("0.3", "1e-3", "0.9", "0.4"),
    ] {
        let common = [
            "bound",
            "--law",
            "kinematic",
            "--ke",
            ke,
            "--zeta",
            zeta,
            "--gamma",
            gamma,
        ];
        let inv = json(&echelon(
            &[&common[..], &["--max-e", max_e, "--ts", "0.02", "--json"]].concat(),
        ));
        let (z, g, e): (f64, f64, f64) = (
            zeta.parse().unwrap(),
            gamma.parse().unwrap(),
            max_e.parse().unwrap(),
        );
        let per = 2f64.sqrt() * z / g;
        let n = inv["steps"].as_u64().unwrap();
        assert!(n as f64 * per <= e && (n + 1) as f64 * per > e, "{inv}");
        assert!((inv["fix_period_s"].as_f64().unwrap() - 0.02 * n as f64).abs() < 1e-9);
        let n_text = n.to_string();
        let fwd = json(&echelon(
            &[&common[..], &["--steps", &n_text, "--json"]].concat(),
        ));
        assert!((fwd["e_bound"].as_f64().unwrap() - n as f64 * per).abs() < 1e-12);
        let want_z = 2f64.sqrt() * ke.parse::<f64>().unwrap() * z * n as f64;
        assert!((fwd["z_bound"].as_f64().unwrap() - want_z).abs() < 1e-12 * want_z.max(1.0));
    }
    assert_refused(
        &echelon(&[
            "bound",
            "--law",
            "kinematic",
            "--zeta",
            "1e-4",
            "--max-z",
            "0.1",
        ]),
        &["--max-e"],
    );
    assert_refused(
        &echelon(&["bound", "--zeta", "1e-4", "--steps", "10"]),
        &["--omega-max"],
    );
    // The kinematic bound depends on neither K_z nor ω_M: given, each is
    // refused at its flag rather than silently ignored.
    for (flag, value) in [("--omega-max", "2.84"), ("--kz", "10")] {
        let kinematic = [
            "bound",
            "--law",
            "kinematic",
            "--zeta",
            "1e-4",
            "--steps",
            "10",
        ];
        assert_refused(
            &echelon(&[&kinematic[..], &[flag, value]].concat()),
            &[flag, "kinematic", "--law dynamic"],
        );
    }
}

#[test]
fn bound_refuses_inputs_outside_the_theorem() {
    let bound = ["bound", "--zeta", "1e-4", "--omega-max", "1"];
    for (args, needle) in [
        (&["--gamma", "1"][..], "gamma"),
        (&["--gamma", "0"], "gamma"),
        (&["--ke", "-1"], "--ke"),
        (&["--kz", "0"], "--kz"),
        (&["--zeta", "0"], "--zeta"),
    ] {
        let all = [&bound[..], &["--steps", "10"], args].concat();
        assert_refused(&echelon(&all), &[needle]);
    }
    assert_refused(&echelon(&bound), &["--steps"]);
    assert_refused(
        &echelon(&[&bound[..], &["--steps", "0"]].concat()),
        &["--steps 0"],
    );
}

/// A value Theorem 2 refuses is named by the flag that gave it, with the
/// value given: `--max-e 1e300` was refused as `max_z = 1.5e300` (the ‖z‖
/// it asks for), `--gamma 1` as `gamma = 1`. For both laws, at every
/// magnitude the inverse cannot count.
#[test]
fn a_refused_bound_input_names_its_flag_and_value() {
    let dynamic = ["bound", "--zeta", "1e-3", "--omega-max", "0.5"];
    let kinematic = ["bound", "--zeta", "1e-3", "--law", "kinematic"];
    for exp in [30, 100, 200, 300] {
        let big = format!("1e{exp}");
        for (base, flag) in [
            (&dynamic, "--max-e"),
            (&dynamic, "--max-z"),
            (&kinematic, "--max-e"),
        ] {
            if base == &kinematic && flag == "--max-z" {
                continue;
            }
            let o = echelon(&[&base[..], &[flag, &big]].concat());
            assert_refused(&o, &[&format!("error: {flag} {big}: ")]);
        }
    }
    for gamma in ["1", "1.5", "0", "-0.5"] {
        for base in [&dynamic, &kinematic] {
            let o = echelon(&[&base[..], &["--steps", "10", "--gamma", gamma]].concat());
            assert_refused(&o, &[&format!("error: --gamma {gamma}: must be in (0, 1)")]);
        }
    }
}

/// The inverse over random inputs of both laws, well beyond the examples
/// (gains 0.05–50, ζ 1e-7–1e-2 m, ω_M 0–5 rad/s, any γ, targets from a
/// hundredth to a thousand times one sample's bound): either the printed N
/// is the largest whose closed-form bound stays within the target (exit 0),
/// or no N is (exit 1, one error line naming the flag, nothing on standard
/// output). A target below one sample's bound printed `{"steps": 0,
/// "z_bound": 0.0, "e_bound": 0.0}` and exited 0: bounds of zero, read as
/// holding, where no fix interval holds the target.
#[test]
fn the_inverse_gives_the_largest_n_or_says_there_is_none() {
    // xorshift64*: a fixed stream, no dependency.
    let mut state = 0x9e37_79b9_7f4a_7c15_u64;
    let mut uniform = move || {
        state ^= state >> 12;
        state ^= state << 25;
        state ^= state >> 27;
        (state.wrapping_mul(0x2545_f491_4f6c_dd1d) >> 11) as f64 / (1u64 << 53) as f64
    };
    let (mut none, mut some) = (0, 0);
    let log_uniform = |lo: f64, hi: f64, u: f64| lo * (hi / lo).powf(u);
    for case in 0..150 {
        let (ke, kz, zeta) = (
            log_uniform(0.05, 50.0, uniform()),
            log_uniform(0.05, 50.0, uniform()),
            log_uniform(1e-7, 1e-2, uniform()),
        );
        let omega = 5.0 * uniform();
        let gamma = 0.05 + 0.94 * uniform();
        let kinematic = case % 3 == 0;
        let by_z = !kinematic && case % 2 == 1;
        let sqrt2 = std::f64::consts::SQRT_2;
        // One sample's bound on the quantity asked about.
        let per_step = match (kinematic, by_z) {
            (true, _) => sqrt2 * zeta / gamma,
            (false, true) => sqrt2 * ke * zeta * kz.hypot(omega) / (kz * gamma),
            (false, false) => sqrt2 * zeta * kz.hypot(omega) / (kz * gamma),
        };
        let target = per_step * log_uniform(1e-2, 1e3, uniform());
        let ratio = target / per_step;
        if (ratio - ratio.round()).abs() < 1e-9 * ratio {
            continue; // on a boundary, rounding decides
        }
        let text = |v: f64| format!("{v:e}");
        let (ke_s, kz_s, zeta_s, omega_s, gamma_s, target_s) = (
            text(ke),
            text(kz),
            text(zeta),
            text(omega),
            text(gamma),
            text(target),
        );
        let flag = if by_z { "--max-z" } else { "--max-e" };
        let mut args = vec![
            "bound", "--ke", &ke_s, "--zeta", &zeta_s, "--gamma", &gamma_s, flag, &target_s,
            "--json",
        ];
        if kinematic {
            args.extend(["--law", "kinematic"]);
        } else {
            args.extend(["--kz", &kz_s, "--omega-max", &omega_s]);
        }
        let o = echelon(&args);
        let err = stderr(&o);
        if ratio < 1.0 {
            none += 1;
            assert_eq!(o.status.code(), Some(1), "{args:?}: {err}");
            assert!(stdout(&o).is_empty(), "{args:?}: {}", stdout(&o));
            assert_eq!(err.lines().count(), 1, "{args:?}: {err}");
            assert!(
                err.starts_with(&format!("error: {flag} "))
                    && err.contains("no fix interval keeps")
                    && !err.contains("panicked"),
                "{args:?}: {err}"
            );
        } else {
            some += 1;
            let v = json(&o);
            let n = v["steps"]
                .as_u64()
                .unwrap_or_else(|| panic!("{args:?}: {v}"));
            assert!(
                n >= 1 && n == ratio.floor() as u64,
                "{args:?}: N = {n} for {ratio} samples' worth"
            );
            let bound = if by_z { &v["z_bound"] } else { &v["e_bound"] };
            let bound = bound.as_f64().unwrap();
            assert!(
                bound <= target * (1.0 + 1e-12)
                    && (bound - n as f64 * per_step).abs() <= 1e-12 * bound,
                "{args:?}: {v}"
            );
        }
    }
    assert!(
        none > 10 && some > 10,
        "both outcomes drawn: {none} none, {some} some"
    );
}
