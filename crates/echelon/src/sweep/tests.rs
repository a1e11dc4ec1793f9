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
