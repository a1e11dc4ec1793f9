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
