"""Sweeps: the local sweep is `echelon sweep`'s sweep.csv byte for byte, and
the Ray sweep is the local one byte for byte."""

from __future__ import annotations

import subprocess

import numpy as np
import pytest

import echelon

GRID = {"zeta": [1e-5, 3e-5], "fix_every": [10, 50, 0]}


@pytest.fixture(scope="module")
def local():
    return echelon.sweep(echelon.Scenario.builtin("fix-study", duration=2), GRID, seeds=2)


def test_the_local_sweep_is_the_clis(local, echelon_cli, tmp_path):
    subprocess.run(
        [str(echelon_cli), "sweep", "fix-study", "--duration", "2", "--zeta", "1e-5,3e-5",
         "--fix-every", "10,50,0", "--seeds", "2", "--out", str(tmp_path), "-q"],
        check=True,
    )
    assert local.csv.encode() == (tmp_path / "sweep.csv").read_bytes()
    t = local.table
    assert len(t) == 2 * 3 * 2
    assert list(t["seed"][:2]) == [0, 1]
    # Theorem 2 bounds the runs with fixes, the longer N the larger.
    fixed = t[(t["fix_every"] > 0) & (t["zeta"] == 1e-5)]
    assert fixed["z_bound"].notna().all()
    by_n = fixed.groupby("fix_every")["z_bound"].max()
    assert by_n[50] > by_n[10]
    assert t[t["fix_every"] == 0]["z_bound"].isna().all()


def test_threads_do_not_change_the_bytes(local):
    one = echelon.sweep(echelon.Scenario.builtin("fix-study", duration=2), GRID, seeds=2, threads=1)
    assert one.csv == local.csv


def test_the_ray_sweep_is_the_local_sweep_byte_for_byte(local, tmp_path):
    ray = pytest.importorskip("ray")
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
    try:
        remote = echelon.sweep(
            echelon.Scenario.builtin("fix-study", duration=2), GRID, seeds=2, executor="ray", tasks=5
        )
    finally:
        ray.shutdown()
    assert remote.csv == local.csv
    assert remote.write(tmp_path / "a.csv").read_bytes() == local.write(tmp_path / "b.csv").read_bytes()


def test_bad_grids_are_refused():
    s = echelon.Scenario.builtin("fix-study", duration=1)
    with pytest.raises(TypeError, match="unknown grid key"):
        echelon.sweep(s, {"zzeta": [1]})
    with pytest.raises(ValueError, match="zeta_model"):
        echelon.sweep(s, {"zeta_model": "sideways"})
    with pytest.raises(ValueError, match="gamma"):
        echelon.sweep(s, gamma=2.0)
    with pytest.raises(ValueError, match="executor"):
        echelon.sweep(s, executor="dask")


@pytest.mark.parametrize(
    "key, value", [("zeta", 1e300), ("ed", 1e9), ("slip", 1e300), ("fix_every", 10_000_000_000)]
)
def test_a_value_the_scenario_refuses_names_its_grid_key_as_python_spells_it(key, value):
    s = echelon.Scenario.builtin("fix-study", duration=1)
    with pytest.raises(echelon.ScenarioError) as raised:
        echelon.sweep(s, {key: [value]}, seeds=1)
    e = raised.value
    assert (e.file, e.field, e.line, e.column) == ("arguments", key, 0, 0), str(e)
    assert str(e).startswith(f"arguments: {key}: "), str(e)


@pytest.mark.parametrize(
    "key, value", [("zeta", -1.0), ("ed", 0.0), ("eb", -1.0), ("slip", float("nan"))]
)
def test_a_value_the_grid_refuses_names_its_grid_key_as_python_spells_it(key, value):
    s = echelon.Scenario.builtin("fix-study", duration=1)
    with pytest.raises(ValueError, match=f"^{key} = ") as raised:
        echelon.sweep(s, {key: [value]}, seeds=1)
    assert not isinstance(raised.value, echelon.ScenarioError)


@pytest.mark.parametrize(
    "key, values, twice",
    [
        ("zeta", [1e-4, 2e-4, 0.0001], "0.0001"),
        ("ed", [1.0, 1.0], "1"),
        ("eb", [0.99, 1.01, 0.99], "0.99"),
        ("slip", [0.0, -0.0], "0"),
        ("fix_every", [10, 20, 10], "10"),
    ],
)
def test_a_grid_value_given_twice_is_refused_naming_its_key(key, values, twice):
    s = echelon.Scenario.builtin("fix-study", duration=0.5)
    with pytest.raises(ValueError, match=f"^{key} = {twice}: is given twice"):
        echelon.sweep(s, {key: values}, seeds=1)


def test_repeated_or_no_seeds_are_refused_naming_seeds():
    s = echelon.Scenario.builtin("fix-study", duration=0.5)
    with pytest.raises(ValueError, match="^seeds = 3: is given twice"):
        echelon.sweep(s, {"fix_every": [10]}, seeds=[3, 4, 3])
    for seeds in [0, -2]:
        with pytest.raises(ValueError, match=f"^seeds: {seeds} seeds per combination: .* must be ≥ 1"):
            echelon.sweep(s, {"fix_every": [10]}, seeds=seeds)
    with pytest.raises(ValueError, match="^seeds: an empty list: needs at least one value"):
        echelon.sweep(s, {"fix_every": [10]}, seeds=[])
    with pytest.raises(ValueError, match="^zeta: an empty list"):
        echelon.sweep(s, {"zeta": []}, seeds=1)


@pytest.mark.parametrize(
    "grid, kind, message",
    [
        ({"zeta": "1e-4"}, TypeError, "^zeta: '1e-4' is not a number or a list of numbers"),
        ({"zeta": None}, TypeError, "^zeta: None is not a number"),
        ({"ed": [1.0, "x"]}, TypeError, "^ed: 'x' is not a number"),
        ({"fix_every": [10.7]}, ValueError, "^fix_every: 10.7 is not a whole number"),
        ({"fix_every": [-1]}, ValueError, r"^fix_every: -1 must be a whole number in \[0, 2\*\*64\)"),
        ({"fix_every": [2**64]}, ValueError, "^fix_every: 18446744073709551616 must be"),
        ({"zeta_model": None}, TypeError, "^zeta_model: None"),
    ],
)
def test_a_grid_value_of_the_wrong_kind_names_its_key(grid, kind, message):
    # They were cut (10.7 ran as 10), split into characters, or named an
    # internal field (`GridArgs.fix_every`).
    s = echelon.Scenario.builtin("fix-study", duration=0.5)
    with pytest.raises(kind, match=message):
        echelon.sweep(s, grid, seeds=1)


@pytest.mark.parametrize(
    "kw, message",
    [
        ({"first_seed": -1}, "^first_seed: -1 must be a whole number"),
        ({"first_seed": 2**64 - 1, "seeds": 2}, "^seeds: 2 seeds from first_seed = 18446744073709551615 go past"),
        ({"seeds": [1.5]}, "^seeds: 1.5 is not a whole number"),
        ({"seeds": [2**64]}, "^seeds: 18446744073709551616 must be"),
    ],
)
def test_seeds_out_of_range_name_their_keyword(kw, message):
    s = echelon.Scenario.builtin("fix-study", duration=0.5)
    with pytest.raises(ValueError, match=message):
        echelon.sweep(s, {"fix_every": [10]}, **{"seeds": 1, **kw})


def test_numpy_arrays_and_ranges_are_grid_lists_and_the_last_seed_is_a_seed():
    s = echelon.Scenario.builtin("fix-study", duration=0.5)
    a = echelon.sweep(s, {"zeta": np.array([1e-4, 2e-4]), "fix_every": range(10, 30, 10)}, seeds=np.arange(2))
    b = echelon.sweep(s, {"zeta": [1e-4, 2e-4], "fix_every": [10, 20]}, seeds=[0, 1])
    assert a.csv == b.csv
    last = echelon.sweep(s, {"fix_every": [10.0]}, seeds=1, first_seed=2**64 - 1)
    assert list(last.table["seed"]) == [2**64 - 1]
