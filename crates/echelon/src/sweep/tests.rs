//! The sweep grid's checks and the flags of its fields.

use super::*;
use proptest::prelude::*;

fn valid() -> GridSpec {
    GridSpec {
        zeta: vec![0.0, 1e-4],
        zeta_model: ZetaModel::Wheels,
        wheel_diameter_ratio: vec![1.0],
        wheelbase_ratio: vec![1.002],
        slip: vec![0.0],
        fix_every: vec![0, 50],
        seeds: vec![1, 2],
        gamma: 0.9,
        transient: 1.0,
    }
}

/// A value no grid field takes: negative, zero where positive is
/// needed, not finite, or γ outside (0, 1).
fn bad() -> impl Strategy<Value = f64> {
    prop_oneof![
        Just(f64::NAN),
        Just(f64::INFINITY),
        Just(f64::NEG_INFINITY),
        -1e300..-1e-300,
    ]
}

proptest! {
    /// Whatever the grid refuses, the refusal names a field that has an
    /// `echelon sweep` flag (so the CLI and Python can name it as their
    /// user spelled it), never a name outside the table.
    #[test]
    fn every_refused_grid_value_names_a_field_with_a_flag(which in 0usize..18, v in bad()) {
        let mut g = valid();
        match which {
            0 => g.zeta.clear(),
            1 => g.wheel_diameter_ratio.clear(),
            2 => g.wheelbase_ratio.clear(),
            3 => g.slip.clear(),
            4 => g.fix_every.clear(),
            5 => g.seeds.clear(),
            6 => g.zeta.push(v),
            7 => g.slip.push(v),
            8 => g.wheel_diameter_ratio.push(v),
            9 => g.wheelbase_ratio.push(v),
            10 => g.gamma = if v.is_nan() { v } else { 1.0 - v },
            11 => g.transient = v,
            // A value given twice.
            12 => g.zeta.push(g.zeta[1]),
            13 => g.wheel_diameter_ratio.push(g.wheel_diameter_ratio[0]),
            14 => g.wheelbase_ratio.insert(0, g.wheelbase_ratio[0]),
            15 => g.slip.push(-0.0),
            16 => g.fix_every.insert(1, g.fix_every[0]),
            _ => g.seeds.push(g.seeds[0]),
        }
        let e = Grid::new(g).err();
        prop_assert!(e.is_some(), "case {which} with {v} accepted");
        let field = e.map_or("", |e| e.field);
        prop_assert!(GridSpec::flag(field).is_some(), "{field} has no flag");
    }
}

proptest! {
    /// A list with a value twice is refused naming that value, wherever
    /// the two copies are and whatever the others; the same values
    /// once each are accepted.
    #[test]
    fn a_repeated_value_is_refused_and_named(
        mut zeta in proptest::collection::vec(0.0..1.0f64, 1..40),
        mut seeds in proptest::collection::vec(any::<u64>(), 1..40),
        i in any::<prop::sample::Index>(),
        j in any::<prop::sample::Index>(),
    ) {
        zeta.sort_by(f64::total_cmp);
        zeta.dedup();
        seeds.sort_unstable();
        seeds.dedup();
        let once = GridSpec { zeta: zeta.clone(), seeds: seeds.clone(), ..valid() };
        prop_assert!(Grid::new(once).is_ok());
        let (v, at) = (zeta[i.index(zeta.len())], j.index(zeta.len() + 1));
        zeta.insert(at, v);
        let e = Grid::new(GridSpec { zeta, ..valid() }).unwrap_err();
        prop_assert_eq!((e.field, e.value, &*e.reason), ("zeta", v, REPEATED));
        let (s, at) = (seeds[i.index(seeds.len())], j.index(seeds.len() + 1));
        seeds.insert(at, s);
        let e = Grid::new(GridSpec { seeds, ..valid() }).unwrap_err();
        prop_assert_eq!((e.field, e.value, &*e.reason), ("seeds", s as f64, REPEATED));
    }
}

#[test]
fn an_empty_list_is_worded_as_one_and_a_value_by_its_number() {
    let e = Grid::new(GridSpec {
        seeds: vec![],
        ..valid()
    })
    .unwrap_err();
    assert_eq!(
        GridSpec::refusal(&e),
        "an empty list: needs at least one value"
    );
    let e = Grid::new(GridSpec {
        slip: vec![1e-7, 1e-7],
        ..valid()
    })
    .unwrap_err();
    assert!(
        GridSpec::refusal(&e).starts_with("1e-7 is given twice"),
        "{e}"
    );
}

#[test]
fn the_odometry_fields_keep_their_scenario_keys_and_flags() {
    assert!(Grid::new(valid()).is_ok());
    assert_eq!(GridSpec::flag("wheel_diameter_ratio"), Some("--ed"));
    assert_eq!(GridSpec::flag("wheelbase_ratio"), Some("--eb"));
    assert_eq!(GridSpec::flag("fix_every"), Some("--fix-every"));
    assert_eq!(GridSpec::flag("transient"), Some("--transient"));
    assert_eq!(GridSpec::flag("cases"), None);
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(6))]

    /// Whatever the grid, `run` gives one row per case in grid order and
    /// records each run's divergence in its row: a row is marked diverged
    /// exactly when `run_all` lists its case, at the same time, and a
    /// diverged row's statistics are `inf` and its bounds empty, so a mean
    /// over the seeds of a combination that diverged once is `inf`, never
    /// an average of the runs that ended. (ζ = 0.5 m per sample without a
    /// fix for 1000 samples diverges in `fix-study`; the other cases end.)
    #[test]
    fn run_records_each_runs_divergence_in_its_row(
        absurd in any::<bool>(),
        fixes in proptest::sample::subsequence(vec![1u64, 1000], 1..=2),
        first_seed in 0u64..1000,
        seeds in 1u64..3,
    ) {
        let scenario = Scenario::resolve("fix-study").unwrap();
        let overrides = Overrides { duration: Some(20.0), ..Overrides::default() };
        let grid = Grid::new(GridSpec {
            zeta: if absurd { vec![1e-3, 0.5] } else { vec![1e-3] },
            zeta_model: ZetaModel::Wheels,
            wheel_diameter_ratio: vec![1.0],
            wheelbase_ratio: vec![1.0],
            slip: vec![0.0],
            fix_every: fixes,
            seeds: (first_seed..first_seed + seeds).collect(),
            gamma: 0.99,
            transient: 10.0,
        })
        .unwrap();
        let rows = run(&scenario, &overrides, &grid, &|| ()).unwrap();
        let all = run_all(&scenario, &overrides, &grid, &|| ()).unwrap();
        prop_assert_eq!(&rows, &all.rows);
        let cases: Vec<Case> = rows.iter().map(|r| r.case).collect();
        prop_assert_eq!(cases, grid.cases());
        for r in &rows {
            let listed = all.diverged.iter().find(|d| d.case == r.case);
            prop_assert_eq!(r.diverged, listed.map(|d| d.divergence.t), "{:?}", r);
            let should = r.case.zeta == 0.5 && r.case.fix_every == 1000;
            prop_assert_eq!(r.is_diverged(), should, "{:?}", r);
            let stats = [r.omega_max, r.z_max, r.z_hat_max, r.e_max, r.final_drift, r.drift_max];
            if r.is_diverged() {
                prop_assert!(stats.iter().all(|x| *x == f64::INFINITY), "{:?}", r);
                prop_assert_eq!((r.z_bound, r.z_over_bound, r.e_bound), (None, None, None));
            } else {
                prop_assert!(stats.iter().all(|x| x.is_finite()), "{:?}", r);
            }
        }
        // sweep.csv: one line per row, the diverged ones with their time.
        let mut bytes = Vec::new();
        write_csv(&mut bytes, &rows, ZetaModel::Wheels).unwrap();
        let text = String::from_utf8(bytes).unwrap();
        prop_assert_eq!(text.lines().count(), rows.len() + 1);
        for (line, r) in text.lines().skip(1).zip(&rows) {
            let last = line.rsplit(',').next().unwrap();
            prop_assert_eq!(last.is_empty(), !r.is_diverged(), "{}", line);
        }
        // A mean over a combination's seeds sees the divergence.
        let mean_e = |model: Case| {
            let of: Vec<f64> = rows
                .iter()
                .filter(|r| Case { seed: 0, ..r.case } == model)
                .map(|r| r.e_max)
                .collect();
            of.iter().sum::<f64>() / of.len() as f64
        };
        for r in &rows {
            let m = mean_e(Case { seed: 0, ..r.case });
            prop_assert_eq!(m.is_finite(), !r.is_diverged(), "{:?}", r);
        }
    }
}
