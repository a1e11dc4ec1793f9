//! `echelon run --mcap`'s 3D channels against its CSV.

use super::*;

/// `echelon run --mcap`: the 3D channels carry Foxglove's schemas, and each
/// robot's transform and body equal trajectory.csv's pose at every logged
/// step; the fixed scene holds the reference path and each obstacle.
#[test]
fn run_mcap_3d_channels_are_foxglove_and_match_the_csv() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("run");
    echelon_ok(
        &[
            "run",
            "obstacle-slalom",
            "--duration",
            "2",
            "--mcap",
            "--quiet",
            "--out",
        ],
        &out,
    );
    let read = read_3d(&out.join("run.mcap"));
    check_schemas(&read["schemas"]);
    let csv = std::fs::read_to_string(out.join("trajectory.csv")).unwrap();
    let states: Vec<(f64, u64, f64, f64, f64)> = csv
        .lines()
        .skip(1)
        .map(|l| {
            let v: Vec<&str> = l.split(',').collect();
            let n = |i: usize| v[i].parse::<f64>().unwrap();
            (n(0), v[1].parse().unwrap(), n(2), n(3), n(4))
        })
        .collect();
    assert!(!states.is_empty());
    check_poses(&read, &states);
    let run = echelon::scenario::Scenario::builtin("obstacle-slalom")
        .unwrap()
        .build(&echelon::scenario::Overrides::default())
        .unwrap();
    let obstacles = run.plan.obstacles().len();
    assert!(obstacles > 0);
    let mut want = vec!["reference".to_owned()];
    want.extend((1..=obstacles).map(|i| format!("obstacle/{i}")));
    assert_eq!(read["static"], serde_json::json!(want));
    // docs/foxglove-layout.json draws these channels in `world` and plots a
    // field the state records have.
    let layout: Value = serde_json::from_str(
        &std::fs::read_to_string(
            Path::new(env!("CARGO_MANIFEST_DIR")).join("../../docs/foxglove-layout.json"),
        )
        .unwrap(),
    )
    .unwrap();
    let three_d = &layout["configById"]["3D!echelon"];
    assert_eq!(three_d["followTf"], "world");
    for topic in three_d["topics"].as_object().unwrap().keys() {
        assert!(read["schemas"].get(topic).is_some(), "{topic}");
    }
    let schema = echelon_mcap::AGENT_STATE.schema.to_string();
    for p in layout["configById"]["Plot!echelon"]["paths"]
        .as_array()
        .unwrap()
    {
        let field = p["value"].as_str().unwrap().rsplit('.').next().unwrap();
        assert!(schema.contains(&format!("\"{field}\"")), "{field}");
    }
    // Each leader link starts at its robot.
    for l in read["links"].as_array().unwrap() {
        let k = robot_of(l[1].as_str().unwrap()).unwrap();
        let t = num(&l[0]);
        let s = states
            .iter()
            .find(|s| s.1 == k && (s.0 - t).abs() < 1e-9)
            .unwrap();
        assert_eq!((num(&l[2]), num(&l[3])), (s.2, s.3));
    }
}
