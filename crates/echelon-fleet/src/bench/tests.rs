use super::*;
use echelon::scenario::{Overrides, Scenario};

/// The generated scenario parses, has N agents all following the
/// reference with distinct offsets, and is accepted by the fleet.
#[test]
fn generated_scenarios_are_valid_fleets() {
    for n in [1, 2, 10, 13] {
        let dir = tempfile::tempdir().unwrap_or_else(|e| panic!("{e}"));
        let path = dir.path().join("s.toml");
        std::fs::write(&path, scenario_toml(n)).unwrap_or_else(|e| panic!("{e}"));
        let s = Scenario::resolve(&path.display().to_string()).unwrap_or_else(|e| panic!("{e}"));
        let built = s
            .build(&Overrides::default())
            .unwrap_or_else(|e| panic!("{e}"));
        let agents = built.plan.agents();
        assert_eq!(agents.len(), n);
        for k in 1..=n as u32 {
            crate::robot::agent_spec(&built.plan, k).unwrap_or_else(|e| panic!("{e}"));
        }
        assert_eq!(
            s.fleet().unwrap_or_else(|e| panic!("{e}")).name,
            format!("bench-n{n}")
        );
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
