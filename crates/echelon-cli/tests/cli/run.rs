//! `echelon run` and `echelon plot`: the files written, overrides, odometry,
//! figures, and `lycomp`.

use super::*;

#[test]
fn run_writes_the_documented_files_and_summary() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("run");
    let o = run("nonfeasible", &out, &[]);
    let text = succeeded(&o);
    assert!(
        text.contains("nonfeasible: 1 agent, 10 s at dt = 0.001 s (10000 steps)"),
        "{text}"
    );
    assert!(
        text.contains("robot") && text.contains("reference"),
        "{text}"
    );
    let csv = std::fs::read_to_string(out.join("trajectory.csv")).unwrap();
    let mut lines = csv.lines();
    assert_eq!(
        lines.next(),
        Some("t,agent,x,y,theta,v,omega,ex,ey,zx,zy,u1,u2,tau_r,tau_l")
    );
    assert_eq!(
        lines.next().unwrap().split(',').take(5).collect::<Vec<_>>(),
        ["0", "1", "-4.0", "0.4", "-1.5707963267948966"]
    );
    assert_eq!(csv.lines().count(), 1 + 1001, "every 10 ms from 0 to 10 s");
    let summary: serde_json::Value = summary(&out);
    let agent = &summary["agents"][0];
    for key in [
        "final_pose",
        "final_error",
        "rms_error",
        "peak_torque",
        "settle_time",
    ] {
        assert!(agent.get(key).is_some(), "summary has {key}: {summary}");
    }
    assert!(agent["final_error"].as_f64().unwrap() < 1e-3);
    assert!(agent["settle_time"].as_f64().unwrap() < 10.0);
}

#[test]
fn overrides_change_the_run() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("o");
    let o = run(
        "circle-pentagon",
        &out,
        &[
            "--duration",
            "2",
            "--dt",
            "0.002",
            "--log-dt",
            "0",
            "--law",
            "complete",
            "-q",
        ],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let summary: serde_json::Value = summary(&out);
    assert_eq!(summary["steps"], 1000);
    assert_eq!(summary["dt"], 0.002);
    let rows = std::fs::read_to_string(out.join("trajectory.csv"))
        .unwrap()
        .lines()
        .count()
        - 1;
    assert_eq!(rows, 1001 * 4, "--log-dt 0 logs every step of every agent");
}

#[test]
fn settle_time_is_null_when_never_within_a_centimetre() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("short");
    let o = run("lemniscate-wedge", &out, &["--duration", "0.5", "-q"]);
    assert!(o.status.success());
    let summary: serde_json::Value = summary(&out);
    assert!(summary["agents"][1]["settle_time"].is_null(), "{summary}");
}

#[test]
fn run_writes_odometry_csv_when_agents_dead_reckon() {
    let dir = tempfile::tempdir().unwrap();
    let file = scenario_file(dir.path(), STUDY);
    let out = dir.path().join("r");
    let o = run(&file, &out, &["--seed", "3"]);
    assert!(succeeded(&o).contains("odometry.csv"));
    let odo = std::fs::read_to_string(out.join("odometry.csv")).unwrap();
    assert_eq!(
        odo.lines().next(),
        Some("t,agent,x_hat,y_hat,theta_hat,ex_hat,ey_hat,zx_hat,zy_hat,fix")
    );
    assert_eq!(
        odo.lines().count(),
        std::fs::read_to_string(out.join("trajectory.csv"))
            .unwrap()
            .lines()
            .count()
    );
    // Without odometry no odometry.csv is written.
    let plain = dir.path().join("p");
    assert!(
        run("nonfeasible", &plain, &["--duration", "1", "-q"])
            .status
            .success()
    );
    assert!(!plain.join("odometry.csv").exists());
}

#[test]
fn run_plot_writes_figures_and_report_and_plot_redraws_them() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("cp");
    let o = run("circle-pentagon", &out, &["--duration", "5", "--plot"]);
    let text = succeeded(&o);
    for f in [
        "trajectory.csv",
        "reference.csv",
        "summary.json",
        "scenario.toml",
        "paths.svg",
        "paths.png",
        "errors.svg",
        "errors.png",
        "signals.svg",
        "signals.png",
        "report.html",
    ] {
        assert!(out.join(f).is_file(), "{f} missing");
        assert!(text.contains(f), "stdout does not name {f}: {text}");
    }
    // `plot` works from the directory alone, with the same result.
    let before = std::fs::read(out.join("report.html")).unwrap();
    std::fs::remove_file(out.join("paths.svg")).unwrap();
    let o = echelon(&["plot", out.to_str().unwrap(), "--quiet"]);
    assert!(succeeded(&o).is_empty());
    assert!(out.join("paths.svg").is_file());
    assert!(std::fs::read(out.join("report.html")).unwrap() == before);
    // The recorded scenario names the overrides of the run.
    let scenario = std::fs::read_to_string(out.join("scenario.toml")).unwrap();
    assert!(scenario.contains("# overrides: --duration 5"), "{scenario}");
}

#[test]
fn plot_refuses_a_directory_that_is_not_a_run() {
    let dir = tempfile::tempdir().unwrap();
    let o = echelon(&["plot", dir.path().to_str().unwrap()]);
    assert_refused(&o, &["summary.json"]);
    std::fs::write(dir.path().join("summary.json"), "{").unwrap();
    let o = echelon(&["plot", dir.path().to_str().unwrap()]);
    assert_refused(&o, &["summary.json", "EOF"]);
    assert!(!dir.path().join("report.html").exists());
}

#[test]
fn lycomp_prints_the_largest_gap_and_writes_fig_5() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("ly");
    let o = echelon_into(&out, &["lycomp", "--lxoff", "0.5"]);
    let text = succeeded(&o);
    // docs/control-law.md: the largest gap is 0.23 m, near |R_C| = 0.7.
    assert!(
        text.contains("largest gap to eq. 5: 0.230 m at |R_C| = 0.705 m"),
        "{text}"
    );
    assert!(!text.contains("least squares"));
    assert!(out.join("lycomp.svg").is_file() && out.join("lycomp.png").is_file());
    let svg = std::fs::read_to_string(out.join("lycomp.svg")).unwrap();
    assert!(svg.contains("R_C [m]") && svg.contains("L_Ycomp [m]"));

    let o = echelon_into(&out, &["lycomp", "--fit", "--lxoff", "0.5"]);
    let text = succeeded(&o);
    assert!(
        text.contains("eq. 6, least squares   G = 0.213724  δ = 0.450806  ε = 0.702275  largest gap to eq. 5: 0.122 m"),
        "{text}"
    );
    // Outside the paper's range: a warning and the refit.
    let o = echelon_into(&out, &["lycomp", "--lxoff", "2"]);
    assert!(o.status.success());
    assert!(stderr(&o).starts_with("warning: the paper's polynomials"));
    assert!(stdout(&o).contains("least squares"));
    for bad in ["0", "-1", "nan", "x"] {
        assert_refused(&echelon(&["lycomp", "--lxoff", bad]), &["--lxoff"]);
    }
}

/// The summary's safety lines say what `summary.json` says: the closest
/// approach (to the printed precision), between whom, against the radius; a
/// warning exactly when the robots came more than 1 mm inside it, and one
/// naming exactly the robots deadlocked at the end. A velocity base's torque
/// cell is a dash, not a measured 0.
#[test]
fn run_prints_the_safety_filters_outcome_as_its_summary_has_it() {
    let dir = tempfile::tempdir().unwrap();
    let deadlock = dir.path().join("deadlock-crossing.toml");
    std::fs::write(&deadlock, include_str!("deadlock-crossing.toml")).unwrap();
    for (scenario, velocity) in [
        ("crossing", true),
        ("obstacle-slalom", false),
        (deadlock.to_str().unwrap(), false),
    ] {
        let out = dir.path().join("out");
        let o = run(scenario, &out, &[]);
        let text = succeeded(&o);
        let err = stderr(&o);
        let s = summary(&out);
        let safety = &s["safety"];
        let names: Vec<&str> = s["agents"]
            .as_array()
            .unwrap()
            .iter()
            .map(|a| a["name"].as_str().unwrap())
            .collect();
        let name = |k: &serde_json::Value| names[k.as_u64().unwrap() as usize - 1];
        let (d, radius) = (
            safety["min_distance"].as_f64().unwrap(),
            safety["radius"].as_f64().unwrap(),
        );
        let pair = &safety["min_distance_agents"];
        let line = format!(
            "safety: closest approach {d:.4} m ({} and {}, t = {:.2} s), radius {radius} m",
            name(&pair[0]),
            name(&pair[1]),
            safety["min_distance_t"].as_f64().unwrap()
        );
        assert!(text.contains(&line), "{scenario}: `{line}` not in\n{text}");
        assert!(
            text.contains(&format!(
                "filter acted on {} agent-steps, braked {} (infeasible), {} deadlock breaks",
                safety["active"], safety["infeasible"], safety["deadlock_breaks"]
            )),
            "{scenario}: {text}"
        );
        assert_eq!(
            err.contains("inside the safety radius"),
            d < radius - 1e-3,
            "{scenario}: {d} against {radius}: {err}"
        );
        let deadlocked: Vec<&str> = safety["deadlocked_at_end"]
            .as_array()
            .unwrap()
            .iter()
            .map(name)
            .collect();
        let warned = err
            .lines()
            .find_map(|l| l.strip_prefix("warning: deadlocked by the safety filter at the end: "));
        match warned {
            Some(list) => assert_eq!(list.split(", ").collect::<Vec<_>>(), deadlocked),
            None => assert!(
                deadlocked.is_empty(),
                "{scenario}: {deadlocked:?} not named: {err}"
            ),
        }
        let rows: Vec<&str> = text
            .lines()
            .filter(|l| {
                names
                    .iter()
                    .any(|n| l.trim_start().starts_with(&format!("{n} ")))
            })
            .collect();
        assert_eq!(rows.len(), names.len(), "{scenario}: {text}");
        for row in rows {
            assert_eq!(row.contains(" — "), velocity, "{scenario}: {row}");
            assert_eq!(row.contains("N·m"), !velocity, "{scenario}: {row}");
        }
    }
}

/// The closest approach `echelon run` printed, m.
fn printed_closest_approach(text: &str) -> f64 {
    let rest = text
        .lines()
        .find_map(|l| l.trim_start().strip_prefix("safety: closest approach "))
        .unwrap_or_else(|| panic!("no closest approach in\n{text}"));
    rest.split(' ').next().unwrap().parse().unwrap()
}

/// Two TurtleBot 4s (lag 0.1 s, 0.306 m/s) on a line swap sides, nearly
/// head on: the filter, which treats a lagged base as of relative degree
/// two, keeps their points at least `radius − 1 mm` apart, as printed, and
/// both arrive. Their backup limit is lifted (a Create 3 with its
/// `safety_override`): the filter backs one of them up further than the
/// Create 3's 10 cm to let the other pass, and it does not know the limit
/// (with it, that robot creeps and never arrives: docs/real-robots.md,
/// "Backing up").
#[test]
fn two_turtlebot4s_swapping_sides_keep_the_radius() {
    let dir = tempfile::tempdir().unwrap();
    let radius = 0.4;
    let mut text = format!(
        "name = \"swap\"\n[sim]\nduration = 60.0\ndt = 0.01\n[log]\ndt = 0.05\n\
         [control]\nlaw = \"kinematic\"\nke = 1.0\nl = 0.05\nlycomp = \"none\"\n\
         [robots.tb4]\npreset = \"turtlebot4\"\nreverse_limit = 1000.0\n\
         [reference.line]\nspeed = 0.0\nstart = {{ x = 3.0, y = 0.0, theta = 0.0 }}\n\
         [safety]\nradius = {radius}\ngain = 1.0\n"
    );
    // Each holds the other's start: the slot is (−x, −y) of the offset from
    // the reference, at rest 3 m ahead (the law needs L_X > 0).
    for (x, y, theta) in [(-1.2, 0.03, 0.0), (1.2, -0.02, 3.1)] {
        text += &format!(
            "[[agents]]\nrobot = \"tb4\"\nstart = {{ x = {x}, y = {y}, theta = {theta} }}\n\
             leader = \"reference\"\noffset = {{ x = {}, y = {y} }}\n",
            3.0 + x
        );
    }
    let file = scenario_file(dir.path(), &text);
    let out = dir.path().join("out");
    let o = run(&file, &out, &[]);
    let printed = succeeded(&o);
    let closest = printed_closest_approach(&printed);
    assert!(closest >= radius - 1e-3, "closest {closest}\n{printed}");
    let s = summary(&out);
    let d = s["safety"]["min_distance"].as_f64().unwrap();
    assert!((d - closest).abs() <= 5e-5, "{d} printed as {closest}");
    assert!(
        !stderr(&o).contains("inside the safety radius"),
        "{}",
        stderr(&o)
    );
    for a in s["agents"].as_array().unwrap() {
        let e = a["final_error"].as_f64().unwrap();
        assert!(e < 0.01, "{a}");
    }
}

/// A run with `[safety]` whose gains blow it up (the law's `ke` absurd, the
/// barrier's `γ` at its largest) stops with exit 1 and the divergence
/// guard's message, no panic (the filters pass a state or nominal that is
/// not finite on unchanged: their unit tests). Velocity bases (the
/// first-order and the lagged filter) and torque-driven robots alike.
#[test]
fn a_filtered_run_whose_gains_blow_it_up_exits_1_as_diverged() {
    let dir = tempfile::tempdir().unwrap();
    let robots = [
        "[robots.r]\npreset = \"agent1\"\n",
        "[robots.r]\ndrive = \"velocity\"\npreset = \"ideal\"\n",
        // (lags without limits: a base with limits cannot leave the bounds)
        "[robots.r]\ndrive = \"velocity\"\npreset = \"ideal\"\ntau_v = 0.05\ntau_omega = 0.05\n",
    ];
    for (k, robot) in robots.iter().enumerate() {
        let law = if k == 0 { "complete" } else { "kinematic" };
        let mut text = format!(
            "[sim]\nduration = 5.0\ndt = 0.001\n[control]\nlaw = \"{law}\"\nke = 1e12\nkz = 1e12\n\
             l = 0.05\nlycomp = \"none\"\n{robot}\
             [reference.line]\nspeed = 0.5\nstart = {{ x = 0.0, y = 0.0, theta = 0.0 }}\n\
             [safety]\nradius = 0.3\ngain = 1e4\n"
        );
        if k != 0 {
            // (the kinematic law has no kz)
            text = text.replace("kz = 1e12\n", "");
        }
        for (x, y) in [(-1.0, 0.6), (-1.0, -0.6)] {
            text += &format!(
                "[[agents]]\nrobot = \"r\"\nstart = {{ x = {x}, y = {y}, theta = 0.0 }}\n\
                 leader = \"reference\"\noffset = {{ x = 0.5, y = {y} }}\n"
            );
        }
        let file = scenario_file(dir.path(), &text);
        let o = run(&file, &dir.path().join("out"), &[]);
        let err = stderr(&o);
        assert!(!err.contains("panicked"), "{robot}: {err}");
        assert_eq!(o.status.code(), Some(1), "{robot}: {err}");
        assert!(err.contains(") diverged at t = "), "{robot}: {err}");
    }
}
