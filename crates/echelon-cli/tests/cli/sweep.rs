//! `echelon sweep` and `echelon umbmark`.

use super::*;

#[test]
fn sweep_writes_one_row_per_run_the_same_on_any_thread_count() {
    let dir = tempfile::tempdir().unwrap();
    let file = scenario_file(dir.path(), STUDY);
    let run = |threads: &str, out: &str| {
        let out = dir.path().join(out);
        let o = echelon_into(
            &out,
            &[
                "sweep",
                &file,
                "--zeta",
                "1e-5,2e-5",
                "--fix-every",
                "0,100,500",
                "--slip",
                "0,1e-6",
                "--seeds",
                "2",
                "--threads",
                threads,
            ],
        );
        assert!(o.status.success(), "{}", stderr(&o));
        (
            stdout(&o),
            std::fs::read_to_string(out.join("sweep.csv")).unwrap(),
        )
    };
    let (text, one) = run("1", "a");
    for f in ["drift.csv", "sweep.svg", "sweep.png"] {
        assert!(dir.path().join("a").join(f).exists(), "{f}");
    }
    let (_, two) = run("2", "b");
    assert_eq!(one, two, "sweep.csv depends on the thread count");
    let mut lines = one.lines();
    assert_eq!(lines.next().unwrap(), echelon::sweep::SWEEP_HEADER);
    assert_eq!(lines.count(), 2 * 3 * 2 * 2, "ζ × N × slip × seeds");
    assert!(text.contains("24 runs on 1 threads"), "{text}");
    // Rows under Theorem 2's assumptions carry the bound, and respect it.
    for row in one.lines().skip(1) {
        let cells: Vec<&str> = row.split(',').collect();
        let (slip, n, ratio) = (cells[4], cells[5], cells[14]);
        if slip == "0.0" && n != "0" {
            assert!(ratio.parse::<f64>().unwrap() < 1.0, "{row}");
        } else {
            assert!(ratio.is_empty(), "no bound outside the theorem: {row}");
        }
    }
    assert_refused(&echelon(&["sweep", &file, "--gamma", "1"]), &["gamma"]);
    assert_refused(&echelon(&["sweep", &file, "--ed", "0"]), &["--ed"]);
}

#[test]
fn a_velocity_sweep_fills_the_bound_columns_with_the_kinematic_form() {
    // The ideal velocity bases of circle-pentagon-velocity under the kinematic
    // law: z_bound = √2 K_e N ζ, e_bound = √2 N ζ / γ, ratio ‖e‖/e_bound.
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("v");
    let o = echelon_into(
        &out,
        &[
            "sweep",
            "circle-pentagon-velocity",
            "--zeta-model",
            "worst-case",
            "--fix-every",
            "0,100",
            "--seeds",
            "1",
            "--duration",
            "14",
            "--transient",
            "10",
        ],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stdout(&o).contains("‖e‖/e bound"), "{}", stdout(&o));
    let csv = std::fs::read_to_string(out.join("sweep.csv")).unwrap();
    let rows: Vec<Vec<&str>> = csv
        .lines()
        .skip(1)
        .map(|l| l.split(',').collect())
        .collect();
    assert_eq!(rows.len(), 2);
    assert!(rows[0][13].is_empty(), "no fixes, no bound");
    let num = |c: &str| c.parse::<f64>().unwrap();
    let r = &rows[1];
    let (e_max, z_bound, ratio, e_bound) = (num(r[10]), num(r[13]), num(r[14]), num(r[15]));
    let sqrt2 = std::f64::consts::SQRT_2;
    assert!((z_bound - sqrt2 * 1.5 * 100.0 * 1e-5).abs() < 1e-15);
    assert!((e_bound - sqrt2 * 100.0 * 1e-5 / 0.99).abs() < 1e-15);
    assert!(
        (ratio - e_max / e_bound).abs() < 1e-12 && ratio < 1.0,
        "{r:?}"
    );
}

#[test]
fn umbmark_estimates_and_writes_its_results() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("u");
    let o = echelon_into(
        &out,
        &[
            "umbmark", "--ed", "1.004", "--eb", "1.015", "--slip", "1e-7", "--seed", "2", "--json",
        ],
    );
    let c = json(&o);
    let ed = c["refined"]["ed"].as_f64().unwrap();
    let eb = c["refined"]["eb"].as_f64().unwrap();
    assert!(
        (ed - 1.004).abs() < 0.1 * 0.004 && (eb - 1.015).abs() < 0.1 * 0.015,
        "{c}"
    );
    let csv = std::fs::read_to_string(out.join("umbmark.csv")).unwrap();
    assert_eq!(csv.lines().count(), 1 + 10);
    assert!(out.join("calibration.json").exists());
    let text = stdout(&echelon(&["umbmark", "--ed", "1.004", "--eb", "1.015"]));
    assert!(
        text.contains("Borenstein") && text.contains("corrections: left wheel diameter ×"),
        "{text}"
    );
    // Large errors: the fit is the robot's (it once printed E_d = 0.887,
    // E_b = 0.439 for these), and says nothing against itself.
    let c = json(&echelon(&[
        "umbmark", "--ed", "1.1", "--runs", "1", "--json",
    ]));
    assert!(
        (c["refined"]["ed"].as_f64().unwrap() - 1.1).abs() < 1e-9
            && (c["refined"]["eb"].as_f64().unwrap() - 1.0).abs() < 1e-9
            && c["warnings"].as_array().unwrap().is_empty(),
        "{c}"
    );
    // Beyond what the square tells apart (a wheelbase a third of nominal):
    // said so, with the best fit it is not.
    let text = stdout(&echelon(&["umbmark", "--eb", "0.33", "--runs", "1"]));
    assert!(
        text.contains("warning: no E_d in [0.67, 1.5] and E_b in [0.6, 2]")
            && text.contains("not the robot's"),
        "{text}"
    );
    assert_refused(
        &echelon(&["umbmark", "--robot", "agent9"]),
        &["unknown robot"],
    );
    assert_refused(
        &echelon(&["umbmark", "--from-log", "/no/such/run"]),
        &["/no/such/run"],
    );
}

/// A sweep whose grid reaches an absurd error model (ζ = 0.5 m per sample,
/// no fix for 1000 samples) does not stop at the first divergence, nor
/// drop it from what it shows: every case is a row of sweep.csv, a diverged
/// one with its `diverged` time and `inf` statistics (so a mean or maximum
/// over its seeds is `inf`, not an average of the runs that ended), and a
/// line of diverged.csv; the table marks how many of each combination's
/// seeds diverged and the sweep how many in all; the command fails with 1
/// (not 2: nothing was refused) naming the count, and a later sweep that
/// does not diverge into the same directory removes the stale list.
#[test]
fn a_sweep_goes_on_past_divergent_cases_lists_them_and_fails() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("sw");
    let grid = |zeta: &str| {
        echelon_into(
            &out,
            &[
                "sweep",
                "fix-study",
                "--zeta",
                zeta,
                "--fix-every",
                "1,1000",
                "--seeds",
                "2",
                "--duration",
                "20",
            ],
        )
    };
    let o = grid("0.001,0.5");
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(!err.contains("panicked"), "{err}");
    let read = |f: &str| std::fs::read_to_string(out.join(f)).unwrap();
    let (rows, diverged) = (read("sweep.csv"), read("diverged.csv"));
    let mut diverged_lines = diverged.lines();
    assert_eq!(diverged_lines.next(), Some(echelon::sweep::DIVERGED_HEADER));
    // (ζ, N, seed) of each case: columns 0, 5 and 6 of both files.
    let case = |line: &str| {
        let c: Vec<String> = line.split(',').map(str::to_owned).collect();
        (c[0].clone(), c[5].clone(), c[6].clone())
    };
    let header: Vec<&str> = echelon::sweep::SWEEP_HEADER.split(',').collect();
    let column = |name: &str| header.iter().position(|h| *h == name).unwrap();
    let ran: Vec<_> = rows.lines().skip(1).map(case).collect();
    let failed: Vec<_> = diverged.lines().skip(1).map(case).collect();
    assert!(!failed.is_empty(), "ζ = 0.5 m without fixes diverges");
    assert_eq!(ran.len(), 2 * 2 * 2, "a row per case: ζ × N × seeds");
    for zeta in ["0.001", "0.5"] {
        for n in ["1", "1000"] {
            for seed in ["0", "1"] {
                let c = (zeta.to_owned(), n.to_owned(), seed.to_owned());
                assert!(ran.contains(&c), "{c:?} missing");
            }
        }
    }
    // A row is marked diverged exactly when diverged.csv lists its case,
    // at the same time, with statistics that no average can hide.
    for (line, c) in rows.lines().skip(1).zip(&ran) {
        let cells: Vec<&str> = line.split(',').collect();
        let when = cells[column("diverged")];
        match diverged.lines().skip(1).find(|l| case(l) == *c) {
            Some(d) => {
                assert_eq!(when, d.split(',').nth(8).unwrap(), "{line} / {d}");
                for stat in ["z_max", "e_max", "drift_max"] {
                    assert_eq!(cells[column(stat)], "inf", "{stat}: {line}");
                }
                assert!(cells[column("z_bound")].is_empty(), "{line}");
            }
            None => {
                assert!(when.is_empty(), "{line}");
                assert!(cells[column("e_max")].parse::<f64>().unwrap().is_finite());
            }
        }
    }
    for line in diverged_lines {
        // What left its bound, beyond it (a finite value with a bound).
        let c: Vec<&str> = line.split(',').collect();
        let (value, bound) = (c[10].parse::<f64>().unwrap(), c[11].parse::<f64>().unwrap());
        assert!(value > bound, "{line}");
    }
    assert!(
        err.contains(&format!("{} of 8 runs diverged", failed.len())),
        "{err}"
    );
    // The table: the count in its first line, and per combination how many
    // of its seeds diverged (ζ = 0.5 m without fixes: both).
    let table = stdout(&o);
    assert!(
        table.contains(&format!("{} diverged", failed.len())),
        "{table}"
    );
    let row_of = |zeta: &str, n: &str| {
        table
            .lines()
            .find(|l| {
                let w: Vec<&str> = l.split_whitespace().collect();
                w.first() == Some(&zeta) && w.get(4) == Some(&n)
            })
            .unwrap_or_else(|| panic!("no row for ζ = {zeta}, N = {n}: {table}"))
            .to_owned()
    };
    let both = row_of("5.0e-1", "1000");
    assert!(both.trim_end().ends_with("2/2"), "{both}");
    assert!(both.contains("inf"), "{both}");
    let none = row_of("1.0e-3", "1");
    assert!(none.trim_end().ends_with("0/2"), "{none}");
    let o = grid("0.001");
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(!out.join("diverged.csv").exists(), "a stale diverged.csv");
}

/// A list value given twice (`--zeta 1,1`, also written another way,
/// `1e-3,0.001`) is refused naming the flag and the value, before any run
/// and without writing the output directory; so is `--seeds 0` (saying what
/// the flag counts) and a seed range past the last seed.
#[test]
fn a_sweep_refuses_repeated_grid_values_and_no_seeds_naming_the_flag() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("sw");
    let sweep = |extra: &[&str]| {
        let mut args = vec!["sweep", "fix-study", "--duration", "0.5", "--seeds", "1"];
        args.extend_from_slice(extra);
        echelon_into(&out, &args)
    };
    for (flag, list, value) in [
        ("--zeta", "1,1", "1"),
        ("--zeta", "1e-3,2e-3,0.001", "0.001"),
        ("--zeta", "0,-0", "0"),
        ("--ed", "1,1.001,1", "1"),
        ("--eb", "0.99,0.99", "0.99"),
        ("--slip", "0,1e-6,0", "0"),
        ("--fix-every", "10,20,50,20", "20"),
    ] {
        let o = sweep(&[flag, list]);
        assert_refused(&o, &[flag, &format!(": {value} is given twice")]);
        assert!(!out.exists(), "{flag} {list}: wrote {}", out.display());
    }
    for seeds in ["0", "-1", "many"] {
        let o = echelon_into(&out, &["sweep", "fix-study", "--seeds", seeds]);
        let err = stderr(&o);
        assert_eq!(o.status.code(), Some(2), "{err}");
        assert!(err.contains("--seeds") && err.contains("≥ 1"), "{err}");
        assert!(!err.contains("needs at least one value"), "{err}");
    }
    let o = echelon_into(
        &out,
        &[
            "sweep",
            "fix-study",
            "--seed",
            "18446744073709551615",
            "--seeds",
            "2",
        ],
    );
    assert_refused(&o, &["--seed", "18446744073709551615"]);
    assert!(!out.exists());
    // The last seed itself is a seed.
    let o = sweep(&["--seed", "18446744073709551615", "--fix-every", "10", "-q"]);
    assert!(o.status.success(), "{}", stderr(&o));
}
