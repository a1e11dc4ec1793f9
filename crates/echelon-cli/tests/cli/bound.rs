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
