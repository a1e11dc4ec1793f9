use super::*;
use echelon::scenario::{Overrides, Scenario};

/// The generated scenario parses, has N agents all following the
/// reference with distinct offsets, and is accepted by the fleet.
#[test]
fn generated_scenarios_are_valid_fleets() {
    for (n, state_rate) in [(1, None), (2, Some(10.0)), (10, None), (13, Some(25.0))] {
        let dir = tempfile::tempdir().unwrap_or_else(|e| panic!("{e}"));
        let path = dir.path().join("s.toml");
        std::fs::write(&path, scenario_toml(n, state_rate)).unwrap_or_else(|e| panic!("{e}"));
        let s = Scenario::resolve(&path.display().to_string()).unwrap_or_else(|e| panic!("{e}"));
        let built = s
            .build(&Overrides::default())
            .unwrap_or_else(|e| panic!("{e}"));
        let agents = built.plan.agents();
        assert_eq!(agents.len(), n);
        for k in 1..=n as u32 {
            crate::robot::agent_spec(&built.plan, k).unwrap_or_else(|e| panic!("{e}"));
        }
        let fleet = s.fleet().unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(fleet.name, format!("bench-n{n}"));
        assert_eq!(fleet.state_rate, state_rate);
    }
}

#[test]
fn bad_sizes_are_refused() {
    let opts = BenchOptions {
        robots: vec![10, 0],
        duration: 1.0,
        out: PathBuf::from("/nonexistent/never-created"),
        exe: PathBuf::from("echelon"),
        log_rate: None,
        robots_per_process: None,
        hosts: Vec::new(),
    };
    let err = run(&opts, &StopFlag::new(), |_| {}).err();
    assert!(matches!(err, Some(FleetError::Config(_))), "{err:?}");
    assert!(!opts.out.exists());
}
