//! A new user's bad inputs: each exits 2 with one line naming the file,
//! line, column and field (or the flag), and writes nothing.

use super::*;

const HEAD: &str = "[sim]\nduration = 1.0\ndt = 0.01\n\n";
const AGENT: &str = "\n[[agents]]\nstart = { x = -1.0, y = 0.0, theta = 0.0 }\nleader = \"reference\"\noffset = { x = 0.5, y = 0.0 }\n";

fn waypoints(body: &str) -> String {
    format!("{HEAD}[reference.waypoints]\n{body}\n{AGENT}")
}

/// `echelon ARGS… --out OUT` is refused naming each needle, and OUT is not created.
fn refused_writing_nothing(args: &[&str], out: &Path, needles: &[&str]) {
    let mut all = args.to_vec();
    all.extend(["--out", out.to_str().unwrap()]);
    assert_refused(&echelon(&all), needles);
    assert!(!out.exists(), "{args:?} wrote {}", out.display());
}

#[test]
fn bad_waypoints_and_safety_are_refused_at_their_place() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("never");
    let cases: [(String, &[&str]); 4] = [
        (
            waypoints("points = [[0.0, 0.0, 0.0], [1e-9, 1.0, 0.0], [2.0, 2.0, 0.0]]"),
            &[
                "s.toml:6:28: reference.waypoints.points[2]",
                "t = 1e-9 s",
                "t = 0 s",
                "1e-6 s apart",
            ],
        ),
        (
            waypoints("points = [[0.0, 0.0, 0.0], [1.0, 600.0, 800.0]]"),
            &[
                "s.toml:6:28: reference.waypoints.points[2]",
                "t = 0 s and t = 1 s",
                "1000 m/s",
            ],
        ),
        (
            waypoints("points = [[0.0, 0.0, 0.0], [1.0, 60.0, 0.0]]"),
            &[
                "s.toml:6:",
                "reference.waypoints.points[",
                "space the waypoints more evenly",
            ],
        ),
        (
            waypoints("points = [[0.0, 0.0, 0.0], [10.0, 1.0, 0.0]]")
                .replace("leader = ", "safety = { gain = 2.0 }\nleader = "),
            &["s.toml:10:10: agents[1].safety", "[safety]"],
        ),
    ];
    for (text, needles) in cases {
        let f = scenario_file(dir.path(), &text);
        refused_writing_nothing(&["run", &f], &out, needles);
    }
}

#[test]
fn bad_waypoint_csv_files_are_refused_at_their_cell() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("never");
    let f = scenario_file(dir.path(), &waypoints("file = \"w.csv\""));
    let csv = dir.path().join("w.csv");
    let shown = csv.display().to_string();
    for (text, at, more) in [
        ("t,x,z\n0,0,0\n1,1,0\n", ":1:5: y: ", "no column `y`"),
        ("time,x,y\n0,0,0\n1,1,0\n", ":1:1: t: ", "no column `t`"),
        // A column named twice was read from one of the two, silently.
        (
            "t,t,x,y\n0,9,0,0\n1,9,1,0\n",
            ":1:3: t: ",
            "column `t` twice",
        ),
        (
            "t,x,y,x\n0,0,0,5\n1,1,0,5\n",
            ":1:7: x: ",
            "column `x` twice",
        ),
        ("t,x,y\n0,0,0\n1e-9,1,0\n2,2,0\n", ":3:1: t: ", "t = 1e-9 s"),
        (
            "t,x,y\n0,0,0\n1, nan ,0\n",
            ":3:4: x: ",
            "not a finite number",
        ),
        (
            "t,x,y\n0,0,0\n1,two,0\n",
            ":3:3: x: ",
            "`two` is not a number",
        ),
    ] {
        std::fs::write(&csv, text).unwrap();
        let place = format!("{shown}{at}");
        refused_writing_nothing(&["run", &f], &out, &[&place, more]);
    }
}

#[test]
fn a_bad_flag_is_named_not_a_file_position() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("never");
    // --dt that does not fit the file's log.dt: --dt is to blame.
    refused_writing_nothing(
        &["run", "circle-pentagon", "--dt", "0.7"],
        &out,
        &["error: command line: --dt: 0.7 s does not fit log.dt (builtin:circle-pentagon:13:6)"],
    );
    refused_writing_nothing(
        &["run", "fix-study", "--dt", "0.7"],
        &out,
        &[
            "error: command line: --dt: 0.7 s does not fit sim.controller_period (builtin:fix-study:10:21)",
        ],
    );
    for (flag, value) in [
        ("--zeta", "1e300"),
        ("--ed", "1e9"),
        ("--slip", "1e300"),
        ("--fix-every", "10000000000"),
        ("--gamma", "2"),
    ] {
        let needle = format!("error: command line: {flag}: ");
        refused_writing_nothing(
            &["sweep", "fix-study", flag, value, "--seeds", "1", "-q"],
            &out,
            &[&needle],
        );
    }
}

/// `--dt A --log-dt B` that do not fit: the error is at the flag that broke
/// the fit. circle-pentagon steps 1 ms and logs every 10 ms; a `--log-dt`
/// that is a whole number of its 1 ms steps was fine until `--dt` changed
/// the step, so `--dt` is named (with `--log-dt`'s value); one that is not
/// is refused at `--log-dt` naming `--dt`. `--dt` alone names the file's
/// log.dt and says how to change it; neither flag names the other falsely.
#[test]
fn a_bad_dt_and_log_dt_pair_names_the_flag_that_broke_it() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("never");
    // Steps of 3, 7, 9, 30 ms against periods of 1 ms × 10, 11, 13, 40, 70 ...
    for dt_ms in [3_u32, 7, 9, 30] {
        for log_ms in [10_u32, 11, 13, 40, 70] {
            if log_ms % dt_ms == 0 {
                continue;
            }
            let (dt, log) = (
                format!("{}", f64::from(dt_ms) * 1e-3),
                format!("{}", f64::from(log_ms) * 1e-3),
            );
            let args = ["run", "circle-pentagon", "--dt", &dt, "--log-dt", &log];
            let blame = format!("error: command line: --dt: {dt} s does not fit --log-dt {log} s");
            refused_writing_nothing(
                &args,
                &out,
                &[&blame, "fits the scenario's own dt = 0.001 s"],
            );
        }
        // ... and of 1.5 ms, 2.5 ms: not whole 1 ms steps, so --log-dt is to blame.
        for log in ["0.0015", "0.0025"] {
            let dt = format!("{}", f64::from(dt_ms) * 1e-3);
            let args = ["run", "circle-pentagon", "--dt", &dt, "--log-dt", log];
            let blame = format!(
                "error: command line: --log-dt: {log} s is not 0 (every step) or a whole multiple of dt = {dt} s (--dt)"
            );
            refused_writing_nothing(&args, &out, &[&blame]);
        }
    }
    // --dt alone: the file's log.dt is named, and --log-dt only as the way out.
    let o = echelon(&[
        "run",
        "circle-pentagon",
        "--dt",
        "0.03",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert_refused(
        &o,
        &[
            "--dt: 0.03 s does not fit log.dt (builtin:circle-pentagon:13:6)",
            "change the logging period with --log-dt",
        ],
    );
    assert!(
        !stderr(&o).contains("on the command line: --log-dt"),
        "{}",
        stderr(&o)
    );
    // --log-dt alone: where the step it misfits is.
    refused_writing_nothing(
        &["run", "circle-pentagon", "--log-dt", "0.0015"],
        &out,
        &[
            "--log-dt: 0.0015 s is not 0 (every step) or a whole multiple of dt = 0.001 s (sim.dt, builtin:circle-pentagon:10:6)",
        ],
    );
}

/// Two runs into one directory: the second leaves exactly its own files
/// there. Each built-in run with `--plot --mcap`, then the next built-in
/// (in list order, cyclically) plainly into the same directory: no
/// `odometry.csv`, `safety.csv`, figure, `report.html` or `run.mcap` of the
/// first survives (fix-study's `odometry.csv` used to, and `echelon plot`
/// then failed on it), and `echelon plot` draws the second.
#[test]
fn a_run_into_an_old_run_directory_leaves_only_its_own_files() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let out_s = out.to_str().unwrap();
    let list: Vec<&str> = names().collect();
    let files = |out: &Path| -> Vec<String> {
        let mut v: Vec<String> = std::fs::read_dir(out)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        v.sort();
        v
    };
    for (i, first) in list.iter().enumerate() {
        let second = list[(i + 1) % list.len()];
        let short = ["--duration", "0.05", "--out", out_s];
        let o = echelon(&[&["run", first, "--plot", "--mcap", "-q"][..], &short].concat());
        assert_eq!(o.status.code(), Some(0), "{first}: {}", stderr(&o));
        let o = echelon(&[&["run", second][..], &short].concat());
        assert!(o.status.code() == Some(0), "{second}: {}", stderr(&o));
        // What the second run says it wrote is all there is.
        let said = stdout(&o);
        let wrote = said.lines().find_map(|l| l.strip_prefix("wrote ")).unwrap();
        let mut want: Vec<String> = wrote
            .split(", ")
            .map(|p| {
                Path::new(p)
                    .file_name()
                    .unwrap()
                    .to_string_lossy()
                    .into_owned()
            })
            .collect();
        want.sort();
        assert_eq!(files(&out), want, "{first} then {second}");
        let o = echelon(&["plot", out_s]);
        assert_eq!(
            o.status.code(),
            Some(0),
            "plot after {first} then {second}: {}",
            stderr(&o)
        );
        std::fs::remove_dir_all(&out).unwrap();
    }
}

/// `echelon lycomp` for an `L_Xoff` far from a robot's (1e-300 m, 1e300 m)
/// printed a "fit" of zeros or an infinite gap after one iteration; now the
/// same shape as any λ, scaled, in exponent form. An `--out` that is a file is
/// refused before anything is printed.
#[test]
fn lycomp_fits_any_lxoff_and_refuses_a_file_as_out() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("ly");
    for lxoff in ["1e-300", "1e-9", "3e7", "1e300"] {
        let o = echelon_into(&out, &["lycomp", "--lxoff", lxoff]);
        let text = succeeded(&o);
        assert!(
            !text.contains("inf") && !text.contains("NaN"),
            "{lxoff}: {text}"
        );
        assert!(!text.contains("0.000000"), "{lxoff}: {text}");
        assert!(
            text.contains("e-")
                || text.contains("e2")
                || text.contains("e3")
                || text.contains("e7"),
            "{lxoff}: {text}"
        );
        assert!(
            text.contains("22 Levenberg–Marquardt iterations"),
            "{lxoff}: {text}"
        );
    }
    let file = dir.path().join("f.txt");
    std::fs::write(&file, "mine").unwrap();
    let o = echelon(&["lycomp", "--lxoff", "0.5", "--out", file.to_str().unwrap()]);
    assert_refused(&o, &["--out", "is a file"]);
    assert_eq!(stdout(&o), "");
    assert_eq!(std::fs::read_to_string(&file).unwrap(), "mine");
}
